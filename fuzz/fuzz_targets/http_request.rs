//! Fuzz the node's HTTP service with raw bytes from a TCP client: the real server (hyper on its
//! own thread, the node's limits) on a loopback port, each input written whole and the
//! connection half-closed. Whatever comes back is an HTTP response (or nothing), and after
//! every input `/healthz` still answers: no request may crash or block the service.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::publish::http::{HttpServer, OverlayFn};
use omnirow::status::Shared;
use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpStream};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

fn server() -> SocketAddr {
    static SERVER: OnceLock<(HttpServer, SocketAddr)> = OnceLock::new();
    SERVER
        .get_or_init(|| {
            let overlay: OverlayFn = Arc::new(|_| Err("no frame in the fuzz target".into()));
            let s = HttpServer::start(
                "127.0.0.1:0".parse().unwrap(),
                Arc::new(Shared::new()),
                overlay,
                Arc::default(),
            )
            .expect("HTTP service starts on loopback");
            let addr = s.local_addr();
            (s, addr)
        })
        .1
}

/// Sends `bytes`, half-closes when `half_close` (the end of a fuzz input), and reads the answer
/// to its end. (hyper closes a connection whose client half-closed, possibly before answering
/// a complete request: so the health probe asks `Connection: close` instead.)
fn exchange(addr: SocketAddr, bytes: &[u8], half_close: bool) -> Vec<u8> {
    let mut s = TcpStream::connect(addr).expect("the HTTP service accepts connections");
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(20))).unwrap();
    // The server may answer (e.g. 431) and close before reading everything: not an error.
    let _ = s.write_all(bytes);
    if half_close {
        let _ = s.shutdown(Shutdown::Write);
    }
    let mut out = Vec::new();
    if let Err(e) = s.read_to_end(&mut out) {
        assert!(
            e.kind() == std::io::ErrorKind::ConnectionReset,
            "reading the answer: {e}"
        );
    }
    out
}

fuzz_target!(|data: &[u8]| {
    let addr = server();
    let answer = exchange(addr, data, true);
    assert!(
        answer.is_empty() || answer.starts_with(b"HTTP/1."),
        "not an HTTP response: {:?}",
        String::from_utf8_lossy(&answer[..answer.len().min(200)])
    );
    let health = exchange(
        addr,
        b"GET /healthz HTTP/1.1\r\nHost: fuzz\r\nConnection: close\r\n\r\n",
        false,
    );
    assert!(
        health.starts_with(b"HTTP/1.1 200") || health.starts_with(b"HTTP/1.1 503"),
        "/healthz after the input: {:?}",
        String::from_utf8_lossy(&health[..health.len().min(200)])
    );
});
