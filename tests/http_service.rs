//! The node's HTTP service with real TCP clients: every endpoint, the Prometheus exposition
//! checked by the Prometheus project's own parser (Python `prometheus_client`, from the venv
//! of scripts/ci-python-env.sh), and clients that cannot block one another (half-sent
//! requests, oversized heads).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[path = "support/node.rs"]
mod node;
use node::*;
#[path = "support/http.rs"]
mod http;
use http::*;
#[path = "ros2/venv.rs"]
mod venv;

#[test]
fn endpoints_serve_health_status_history_metrics_and_overlay() {
    let dir = tmpdir("http-endpoints");
    let node = Node::start(&small_config(&dir, ""), &[]);

    let (code, head, body) = node.get("/healthz");
    assert_eq!(code, 200);
    assert_eq!(header(&head, "content-type").unwrap(), "application/json");
    let h: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(h["healthy"], true);
    assert_eq!(h["source"], "streaming");

    let (code, _, body) = node.get("/status");
    assert_eq!(code, 200);
    let s: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(s["schema_version"], 1);
    assert_eq!(s["healthy"], true);
    assert_eq!(s["source_state"], "streaming");
    assert!(s["frames_in"].as_u64().unwrap() >= 1);
    let latest: omnirow::estimate::Estimate =
        serde_json::from_value(s["latest"].clone()).expect("latest is an estimate");
    assert!(latest.seq <= s["frames_in"].as_u64().unwrap());

    // The history fills as frames are published.
    std::thread::sleep(Duration::from_millis(600));
    let (code, _, body) = node.get("/history.json");
    assert_eq!(code, 200);
    let hist: serde_json::Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(hist["window_s"], 60.0);
    let points = hist["points"].as_array().unwrap();
    assert!(points.len() >= 2, "history: {hist}");
    let seqs: Vec<u64> = points.iter().map(|p| p["seq"].as_u64().unwrap()).collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    let now = hist["now_s"].as_f64().unwrap();
    assert!(points.iter().all(|p| p["t_s"].as_f64().unwrap() <= now));

    let (code, head, body) = node.get("/metrics");
    assert_eq!(code, 200);
    assert!(header(&head, "content-type")
        .unwrap()
        .starts_with("text/plain; version=0.0.4"));
    let text = String::from_utf8(body).unwrap();
    for m in [
        "# TYPE omnirow_frames_in_total counter",
        "omnirow_frames_dropped_total ",
        "omnirow_detector_ms{quantile=\"0.99\"} ",
        "omnirow_latency_ms{quantile=\"0.5\"} ",
        "# TYPE omnirow_stage_ms summary",
        "omnirow_stage_ms{stage=\"prepare\",quantile=\"0.5\"} ",
        "omnirow_stage_ms{stage=\"row_fit\",quantile=\"0.99\"} ",
        "omnirow_source_state{state=\"streaming\"} 1",
        "omnirow_pipeline_alive 1",
        "# TYPE omnirow_guidance_tracking gauge",
        "omnirow_guidance_tracking{state=\"coasting\"} ",
        "omnirow_guidance_lateral_offset_m ",
        "omnirow_guidance_heading_error_rad ",
        "omnirow_guidance_row_spacing_m ",
        "# TYPE omnirow_guidance_state_changes_total counter",
        "omnirow_guidance_state_changes_total{to=\"tracking\"} ",
    ] {
        assert!(text.contains(m), "missing `{m}` in\n{text}");
    }
    // The stages' times come from the detector's own timer: the preparation takes time.
    let prepare: f64 = text
        .lines()
        .find_map(|l| l.strip_prefix("omnirow_stage_ms{stage=\"prepare\",quantile=\"0.5\"} "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap();
    assert!(prepare > 0.0, "{text}");
    // One tracking state is the current one.
    let current: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("omnirow_guidance_tracking{") && l.ends_with(" 1"))
        .collect();
    assert_eq!(current.len(), 1, "{text}");

    let (code, head, png) = node.get("/overlay.png");
    assert_eq!(code, 200);
    assert_eq!(header(&head, "content-type").unwrap(), "image/png");
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (408, 342));
    // Rows are drawn in red over the image, the followed line in cyan.
    assert!(img.pixels().any(|p| p.0 == [255, 32, 32]), "no row drawn");
    let followed = img.pixels().filter(|p| p.0 == [0, 230, 255]).count();
    assert!(followed > 100, "{followed} pixels of the followed line");

    let (code, head, body) = node.get("/");
    assert_eq!(code, 200);
    assert!(header(&head, "content-type")
        .unwrap()
        .starts_with("text/html"));
    let page = String::from_utf8(body).unwrap();
    assert!(page.contains("id=\"heading\"") && page.contains("/history.json"));
    // Everything the page needs is served by omnirow.
    assert!(!page.contains("http://") && !page.contains("https://"));

    let (code, head, body) = request(&node.addr, "HEAD", "/status");
    assert_eq!(code, 200);
    assert!(header(&head, "content-length").is_some());
    assert!(body.is_empty());
    assert_eq!(request(&node.addr, "POST", "/status").0, 405);
    assert_eq!(node.get("/nope").0, 404);
    node.stop();
}

#[test]
fn metrics_parse_with_the_prometheus_parser() {
    let Some(venv) = venv::venv("prometheus_client") else {
        return;
    };
    let dir = tmpdir("http-prometheus");
    let node = Node::start(&small_config(&dir, ""), &[]);
    let (_, _, body) = node.get("/metrics");
    node.stop();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/http/check_metrics.py");
    let mut py = Command::new(venv.join("bin/python"))
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    py.stdin.take().unwrap().write_all(&body).unwrap();
    let out = py.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the Prometheus parser rejected /metrics:\n{}{}\n--- /metrics:\n{}",
        stdout,
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&body)
    );
    assert!(stdout.contains("omnirow_frames_in counter"), "{stdout}");
    assert!(stdout.contains("omnirow_latency_ms summary"), "{stdout}");
    // The guidance's series: a state set, its numbers, and the changes (4 states each).
    for family in [
        "omnirow_guidance_tracking gauge 4",
        "omnirow_guidance_lateral_offset_m gauge 1",
        "omnirow_guidance_heading_error_rad gauge 1",
        "omnirow_guidance_row_spacing_m gauge 1",
        "omnirow_guidance_state_changes counter 4",
    ] {
        assert!(stdout.contains(family), "no `{family}` in {stdout}");
    }
}

/// Opens a connection that sends the start of a request and then nothing.
fn half_sent(addr: &str) -> TcpStream {
    let mut s = TcpStream::connect(addr).unwrap();
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: omnirow\r\nUser-Agent: slo")
        .unwrap();
    s
}

#[test]
fn half_sent_requests_do_not_block_health_checks() {
    let dir = tmpdir("http-slow");
    let node = Node::start(&small_config(&dir, ""), &[]);
    let slow: Vec<TcpStream> = (0..50).map(|_| half_sent(&node.addr)).collect();
    // Let the server accept them all before asking.
    std::thread::sleep(Duration::from_millis(200));
    let mut worst = Duration::ZERO;
    for _ in 0..10 {
        let t = Instant::now();
        let (code, _, _) = node.get("/healthz");
        worst = worst.max(t.elapsed());
        assert_eq!(code, 200);
    }
    eprintln!("/healthz with 50 half-sent requests open: slowest of 10 answers {worst:?}");
    // The target is 100 ms (docs/http.md has the measured figure); the bound is generous so
    // that a loaded 2-core CI machine does not make the test flaky. The old one-thread
    // server took over 5 s here.
    assert!(worst < Duration::from_secs(1), "slowest /healthz {worst:?}");

    // The server gives up on a client that does not finish its request head in 5 s.
    let mut s = half_sent(&node.addr);
    s.set_read_timeout(Some(Duration::from_secs(15))).unwrap();
    let t = Instant::now();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let waited = t.elapsed();
    assert!(
        waited >= Duration::from_secs(4) && waited < Duration::from_secs(12),
        "closed after {waited:?}"
    );
    drop(slow);
    node.stop();
}

#[test]
fn oversized_request_heads_are_refused() {
    let dir = tmpdir("http-big");
    let node = Node::start(&small_config(&dir, ""), &[]);
    let mut s = TcpStream::connect(&node.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let filler = "x".repeat(1000);
    let mut head = String::from("GET /healthz HTTP/1.1\r\nHost: omnirow\r\n");
    for i in 0..100 {
        head.push_str(&format!("X-Filler-{i}: {filler}\r\n"));
    }
    head.push_str("\r\n");
    // The server may close before it has read everything: a failed write is a refusal too.
    let _ = s.write_all(head.as_bytes());
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let answer = String::from_utf8_lossy(&buf);
    assert!(
        answer.is_empty() || answer.starts_with("HTTP/1.1 431"),
        "a 100 kB head got: {answer}"
    );
    // And the service still answers.
    assert_eq!(node.get("/healthz").0, 200);
    node.stop();
}
