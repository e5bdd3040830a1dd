//! The node with its HTTP service on a free loopback port, and a plain TCP client for it.
//! Included by the HTTP and live-view tests (`#[path = "support/http.rs"] mod http;`) after
//! `support/node.rs`.
#![allow(dead_code)]

use super::node::{bin, sigterm};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

/// A running `omnirow run` serving HTTP on `addr`; stopped with SIGTERM when dropped.
pub struct Node {
    pub child: Child,
    pub addr: String,
}

impl Node {
    /// Starts `omnirow run --http` with `config` and `args`, and waits (up to 60 s) until an
    /// estimate with a frame has been published.
    pub fn start(config: &Path, args: &[&str]) -> Node {
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let addr = format!("127.0.0.1:{port}");
        let child = bin()
            .args(["run", "--no-print", "--http", &addr, "--config"])
            .arg(config)
            .args(args)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut node = Node { child, addr };
        let t0 = Instant::now();
        loop {
            if let Ok(Some(status)) = node.child.try_wait() {
                panic!("the node exited before serving: {status}");
            }
            if serving(&node.addr) {
                let (code, _, body) = node.get("/status");
                assert_eq!(code, 200);
                let s: serde_json::Value = serde_json::from_slice(&body).unwrap();
                if !s["latest"].is_null() {
                    return node;
                }
            }
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "no estimate within 60 s"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// GET `path` on a new connection: (status code, head, body).
    pub fn get(&self, path: &str) -> (u16, String, Vec<u8>) {
        request(&self.addr, "GET", path)
    }

    /// Stops the node with SIGTERM and checks that it exits cleanly.
    pub fn stop(mut self) {
        sigterm(&self.child);
        assert!(self.child.wait().unwrap().success());
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Whether something listens on `addr`. Before the node listens, a connection to its port
/// can succeed on the client's own socket (TCP's simultaneous open, when the kernel picks
/// that port as the client's ephemeral one): that is not the node.
fn serving(addr: &str) -> bool {
    TcpStream::connect(addr).is_ok_and(|s| s.local_addr().ok() != s.peer_addr().ok())
}

/// One HTTP/1.1 request with `Connection: close`: (status code, head, body). Checks that the
/// body is as long as Content-Length says.
pub fn request(addr: &str, method: &str, path: &str) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).unwrap();
    let split = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("no header end in {:?}", String::from_utf8_lossy(&buf)));
    let head = String::from_utf8_lossy(&buf[..split]).into_owned();
    let code = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    let body = buf[split + 4..].to_vec();
    if let Some(len) = header(&head, "content-length") {
        let len: usize = len.parse().unwrap();
        if method != "HEAD" {
            assert_eq!(len, body.len(), "Content-Length of {path}");
        }
    }
    (code, head, body)
}

/// The value of header `name` (case-insensitive) in `head`.
pub fn header(head: &str, name: &str) -> Option<String> {
    head.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.trim()
            .eq_ignore_ascii_case(name)
            .then(|| v.trim().to_owned())
    })
}
