//! Helpers of the `volgen view` tests: start a server on a free loopback port, and talk HTTP
//! to it over a plain socket, so request targets reach the server exactly as written
//! (an HTTP client library would normalise `/../` away before sending).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::sync::OnceLock;
use std::time::Duration;

/// A running `volgen view`, stopped when dropped.
pub struct ViewServer {
    pub child: Child,
    /// `127.0.0.1:PORT`.
    pub address: String,
    /// What it printed on standard error, read on a thread of its own.
    stderr: mpsc::Receiver<String>,
}

impl ViewServer {
    /// Starts `volgen view` with `args` (a free port is added) and waits for its URL.
    pub fn start(args: &[&str]) -> ViewServer {
        let mut child = Command::new(env!("CARGO_BIN_EXE_volgen"))
            .arg("view")
            .args(args)
            .args(["--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("volgen view starts");
        let stdout = BufReader::new(child.stdout.take().unwrap());
        let (url_tx, url_rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in stdout.lines().map_while(Result::ok) {
                if let Some(at) = line.find("http://") {
                    let address = line[at + 7..].split('/').next().unwrap().to_string();
                    let _ = url_tx.send(address);
                }
            }
        });
        let stderr = BufReader::new(child.stderr.take().unwrap());
        let (err_tx, err_rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                let _ = err_tx.send(line);
            }
        });
        let address = match url_rx.recv_timeout(Duration::from_secs(120)) {
            Ok(address) => address,
            Err(_) => {
                let _ = child.kill();
                let said: Vec<String> = err_rx.try_iter().collect();
                panic!("volgen view printed no URL; stderr: {}", said.join("\n"));
            }
        };
        ViewServer {
            child,
            address,
            stderr: err_rx,
        }
    }

    /// `GET target` (sent as written).
    pub fn get(&self, target: &str) -> Response {
        get(&self.address, target)
    }

    /// A 200 response's body (the response shown otherwise).
    pub fn ok(&self, target: &str) -> Vec<u8> {
        let response = self.get(target);
        assert_eq!(response.status, 200, "{target}: {}", response.text());
        response.body
    }

    /// A 200 JSON response.
    pub fn json(&self, target: &str) -> serde_json::Value {
        serde_json::from_slice(&self.ok(target)).unwrap()
    }

    /// What the server printed on standard error so far.
    pub fn stderr(&self) -> String {
        self.stderr.try_iter().collect::<Vec<_>>().join("\n")
    }

    /// The server's peak resident memory (VmHWM) in KiB.
    #[cfg(target_os = "linux")]
    pub fn peak_kib(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).unwrap();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .unwrap()
    }
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An HTTP response.
#[derive(Debug)]
pub struct Response {
    pub status: u16,
    /// Header lines, lower-cased names.
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Response {
    /// The body as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// The value of header `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// `GET target` on `address` over HTTP/1.1, the target sent exactly as given. The body is
/// `Content-Length` bytes when the response says so (Chromium's DevTools server keeps the
/// connection open after its answer, `Connection: close` or not), else all until the server
/// closes.
pub fn get(address: &str, target: &str) -> Response {
    let mut stream = TcpStream::connect(address).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(120)))
        .unwrap();
    write!(
        stream,
        "GET {target} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut reader = BufReader::new(stream);
    let mut head = Vec::new();
    while !head.ends_with(b"\r\n\r\n") {
        let read = reader.read_until(b'\n', &mut head).unwrap();
        assert!(
            read > 0,
            "{target}: the connection closed inside the header"
        );
    }
    let head = String::from_utf8_lossy(&head).into_owned();
    let mut lines = head.lines();
    let status = lines
        .next()
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .expect("a status line");
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let header = |name: &str| headers.iter().find(|(n, _)| n == name).map(|(_, v)| v);
    let mut body = Vec::new();
    match header("content-length").and_then(|v| v.parse::<usize>().ok()) {
        Some(length) => {
            body.resize(length, 0);
            reader.read_exact(&mut body).unwrap();
        }
        None => {
            reader.read_to_end(&mut body).unwrap();
        }
    }
    if header("transfer-encoding").is_some_and(|v| v.contains("chunked")) {
        body = unchunk(&body);
    }
    Response {
        status,
        headers,
        body,
    }
}

/// Decodes a chunked body.
fn unchunk(mut raw: &[u8]) -> Vec<u8> {
    let mut body = Vec::new();
    loop {
        let line_end = raw.windows(2).position(|w| w == b"\r\n").unwrap();
        let size_text = String::from_utf8_lossy(&raw[..line_end]);
        let size = usize::from_str_radix(size_text.split(';').next().unwrap().trim(), 16).unwrap();
        if size == 0 {
            return body;
        }
        let start = line_end + 2;
        body.extend_from_slice(&raw[start..start + size]);
        raw = &raw[start + size + 2..];
    }
}

/// Whether two files in `format` (an extension) are the same file: byte for byte, but for
/// `.safetensors` up to the order of the header's keys (the writer's metadata is a hash map,
/// whose order changes from one process to the next).
pub fn same_file(format: &str, a: &[u8], b: &[u8]) -> bool {
    if format == "safetensors" {
        same_safetensors(a, b)
    } else {
        a == b
    }
}

/// Whether two `.safetensors` files hold the same header (as JSON) and the same tensor bytes.
pub fn same_safetensors(a: &[u8], b: &[u8]) -> bool {
    let split = |file: &[u8]| -> (serde_json::Value, Vec<u8>) {
        let length = u64::from_le_bytes(file[..8].try_into().unwrap()) as usize;
        let header = serde_json::from_slice(&file[8..8 + length]).expect("a safetensors header");
        (header, file[8 + length..].to_vec())
    };
    split(a) == split(b)
}

/// Trains the `micro` preset (a run with two 3D scales and the upsampler) on a small stones
/// dataset once per test binary, into `name` under cargo's directory for test files (so
/// nothing is left in /tmp: a static is never dropped); returns `(data, run)`.
pub fn micro_run(name: &str) -> &'static (PathBuf, PathBuf) {
    static RUN: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        super::train_micro(&dir)
    })
}
