//! The HTTP endpoint: /healthz, /metrics (Prometheus text format), /overlay.png (the latest
//! frame with its rows and vanishing point drawn), /status (JSON) and / (a page that shows the
//! overlay, refreshed every second).
//!
//! A deliberately small HTTP/1.1 server on std::net: one thread, one request per connection
//! (`Connection: close`), bounded request size and timeouts, GET and HEAD only. It reads the
//! pipeline's shared state; it never slows the pipeline down (the overlay is drawn on request,
//! from the latest frame, and cached per frame).

use crate::source::SourceState;
use crate::status::{Latest, Shared};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Draws the overlay of the latest frame and encodes it as PNG.
pub type OverlayFn = Arc<dyn Fn(&Latest) -> Result<Vec<u8>, String> + Send + Sync>;

/// The running HTTP server.
pub struct HttpServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl HttpServer {
    /// Binds `addr` and serves in a thread.
    pub fn start(
        addr: SocketAddr,
        shared: Arc<Shared>,
        overlay: OverlayFn,
    ) -> std::io::Result<Self> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let st = stop.clone();
        let thread = std::thread::Builder::new()
            .name("http".into())
            .spawn(move || {
                let mut cache: Option<(u64, Vec<u8>)> = None;
                while !st.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((conn, peer)) => {
                            if let Err(e) = serve(conn, &shared, &overlay, &mut cache) {
                                tracing::debug!(%peer, "HTTP: {e}");
                            }
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                            std::thread::sleep(Duration::from_millis(20));
                        }
                        Err(e) => {
                            tracing::warn!("HTTP accept: {e}");
                            std::thread::sleep(Duration::from_millis(100));
                        }
                    }
                }
            })?;
        tracing::info!(%addr, "HTTP endpoint: /healthz /metrics /overlay.png");
        Ok(HttpServer {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops serving and waits for the thread.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for HttpServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

const MAX_REQUEST: u64 = 16 * 1024;

/// Reads a request's line and headers (up to the blank line; the caller bounds the bytes):
/// its method and its path without the query. Empty strings where the line lacks them.
pub fn read_request(reader: &mut impl BufRead) -> std::io::Result<(String, String)> {
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let path = target.split('?').next().unwrap_or("");
    let request = (method.to_string(), path.to_string());
    loop {
        let mut h = String::new();
        if reader.read_line(&mut h)? == 0 || h == "\r\n" || h == "\n" {
            break;
        }
    }
    Ok(request)
}

fn serve(
    conn: TcpStream,
    shared: &Shared,
    overlay: &OverlayFn,
    cache: &mut Option<(u64, Vec<u8>)>,
) -> std::io::Result<()> {
    conn.set_nonblocking(false)?;
    conn.set_read_timeout(Some(Duration::from_secs(2)))?;
    conn.set_write_timeout(Some(Duration::from_secs(5)))?;
    let mut reader = BufReader::new((&conn).take(MAX_REQUEST));
    let (method, path) = read_request(&mut reader)?;
    let (method, path) = (method.as_str(), path.as_str());
    let mut out = &conn;
    if method != "GET" && method != "HEAD" {
        return respond(&mut out, method, 405, "text/plain", b"only GET and HEAD\n");
    }
    match path {
        "/healthz" => {
            let alive = shared.alive();
            let state = shared.source_state();
            let ok = alive && matches!(state, SourceState::Streaming | SourceState::Starting);
            // Detection is what health means; the recording's state is said alongside.
            let recording =
                serde_json::to_string(&shared.status().recording).unwrap_or_else(|_| "\"\"".into());
            let body = format!(
                "{{\"healthy\":{ok},\"pipeline_alive\":{alive},\"source\":\"{}\",\"frames_in\":{},\"recording\":{recording}}}\n",
                state.name(),
                shared.frames_in()
            );
            respond(
                &mut out,
                method,
                if ok { 200 } else { 503 },
                "application/json",
                body.as_bytes(),
            )
        }
        "/metrics" => respond(
            &mut out,
            method,
            200,
            "text/plain; version=0.0.4; charset=utf-8",
            metrics(shared).as_bytes(),
        ),
        "/status" => {
            let body = serde_json::to_string(&shared.status()).unwrap_or_default();
            respond(&mut out, method, 200, "application/json", body.as_bytes())
        }
        "/overlay.png" => match shared.latest() {
            None => respond(&mut out, method, 503, "text/plain", b"no frame yet\n"),
            Some(latest) => {
                let seq = latest.frame.seq;
                if cache.as_ref().map_or(true, |(s, _)| *s != seq) {
                    match overlay(&latest) {
                        Ok(png) => *cache = Some((seq, png)),
                        Err(e) => {
                            let body = format!("overlay: {e}\n");
                            return respond(&mut out, method, 500, "text/plain", body.as_bytes());
                        }
                    }
                }
                let png = &cache.as_ref().expect("filled above").1;
                respond(&mut out, method, 200, "image/png", png)
            }
        },
        "/" => respond(
            &mut out,
            method,
            200,
            "text/html; charset=utf-8",
            INDEX.as_bytes(),
        ),
        _ => respond(&mut out, method, 404, "text/plain", b"not found\n"),
    }
}

const INDEX: &str = "<!doctype html><html><head><meta charset=\"utf-8\"><title>omnirow</title>\
<style>body{background:#222;color:#ddd;font-family:sans-serif}img{max-width:100%}</style></head>\
<body><h1>omnirow</h1><p><a href=\"/metrics\">metrics</a> · <a href=\"/status\">status</a> · \
<a href=\"/healthz\">health</a></p><img id=\"o\" src=\"/overlay.png\">\
<script>setInterval(()=>{document.getElementById('o').src='/overlay.png?'+Date.now()},1000)</script>\
</body></html>\n";

fn respond(
    out: &mut impl Write,
    method: &str,
    code: u16,
    ctype: &str,
    body: &[u8],
) -> std::io::Result<()> {
    let reason = match code {
        200 => "OK",
        404 => "Not Found",
        405 => "Method Not Allowed",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    };
    write!(
        out,
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if method != "HEAD" {
        out.write_all(body)?;
    }
    out.flush()
}

/// The Prometheus text exposition of the pipeline's state.
pub fn metrics(shared: &Shared) -> String {
    use std::fmt::Write as _;
    let s = shared.status();
    let mut m = String::new();
    let mut metric = |name: &str, kind: &str, help: &str, lines: &[(String, f64)]| {
        let _ = writeln!(m, "# HELP {name} {help}");
        let _ = writeln!(m, "# TYPE {name} {kind}");
        for (labels, v) in lines {
            let _ = writeln!(m, "{name}{labels} {v}");
        }
    };
    let plain = |v: f64| vec![(String::new(), v)];
    metric(
        "omnirow_frames_in_total",
        "counter",
        "Frames delivered by the source.",
        &plain(s.frames_in as f64),
    );
    metric(
        "omnirow_frames_out_total",
        "counter",
        "Estimates published for frames.",
        &plain(s.frames_out as f64),
    );
    metric(
        "omnirow_frames_dropped_total",
        "counter",
        "Frames dropped because the detector was busy (oldest first).",
        &plain(s.dropped as f64),
    );
    metric(
        "omnirow_record_dropped_total",
        "counter",
        "Frames or estimates the recorder dropped because the disk was busy.",
        &plain(s.record_dropped as f64),
    );
    metric(
        "omnirow_recorded_frames_total",
        "counter",
        "Frames written to recordings.",
        &plain(s.recorded_frames as f64),
    );
    metric(
        "omnirow_detector_errors_total",
        "counter",
        "Frames the detector failed on.",
        &plain(s.detector_errors as f64),
    );
    metric(
        "omnirow_frames_per_second",
        "gauge",
        "Estimates published per second over the last status interval.",
        &plain(s.fps_out),
    );
    metric(
        "omnirow_detector_ms",
        "summary",
        "Detector time per frame over the last 1024 frames, milliseconds.",
        &[
            ("{quantile=\"0.5\"}".into(), s.detector_p50_ms),
            ("{quantile=\"0.99\"}".into(), s.detector_p99_ms),
        ],
    );
    metric(
        "omnirow_latency_ms",
        "summary",
        "End-to-end latency (frame received to estimate published) over the last 1024 frames, milliseconds.",
        &[
            ("{quantile=\"0.5\"}".into(), s.latency_p50_ms),
            ("{quantile=\"0.99\"}".into(), s.latency_p99_ms),
        ],
    );
    let states = [
        SourceState::Starting,
        SourceState::Streaming,
        SourceState::Lost,
        SourceState::Ended,
    ];
    metric(
        "omnirow_source_state",
        "gauge",
        "The source's state (1 for the current one).",
        &states
            .iter()
            .map(|st| {
                (
                    format!("{{state=\"{}\"}}", st.name()),
                    f64::from(u8::from(*st == s.source_state)),
                )
            })
            .collect::<Vec<_>>(),
    );
    metric(
        "omnirow_pipeline_alive",
        "gauge",
        "1 while every pipeline thread is looping.",
        &plain(f64::from(u8::from(shared.alive()))),
    );
    metric(
        "omnirow_recording",
        "gauge",
        "1 while a recording is being written.",
        &plain(f64::from(u8::from(s.recording.starts_with("recording")))),
    );
    metric(
        "omnirow_recording_failed",
        "gauge",
        "1 when the recording failed or stopped at the disk reserve (detection goes on).",
        &plain(f64::from(u8::from(
            s.recording.starts_with("failed") || s.recording.starts_with("stopped"),
        ))),
    );
    metric(
        "omnirow_estimates_total",
        "counter",
        "Estimates published, by status.",
        &s.status_counts
            .iter()
            .map(|(k, v)| (format!("{{status=\"{k}\"}}"), *v as f64))
            .collect::<Vec<_>>(),
    );
    if let Some(l) = shared.latest() {
        let e = &l.estimate;
        let opt = |v: Option<f64>| v.unwrap_or(f64::NAN);
        metric(
            "omnirow_heading_rad",
            "gauge",
            "Heading of the rows in the latest estimate (NaN without one).",
            &plain(opt(e.heading_rad)),
        );
        metric(
            "omnirow_tilt_rad",
            "gauge",
            "Tilt of the rows in the latest estimate (NaN without one).",
            &plain(opt(e.tilt_rad)),
        );
        metric(
            "omnirow_quality",
            "gauge",
            "Quality of the latest estimate.",
            &plain(e.quality),
        );
        metric(
            "omnirow_last_seq",
            "gauge",
            "Sequence number of the latest published frame.",
            &plain(e.seq as f64),
        );
    }
    m
}
