//! The HTTP service: `/healthz`, `/metrics` (Prometheus text format), `/status` (JSON),
//! `/history.json` (the last minute of estimates), `/overlay.png` (the latest frame in colour
//! with its rows, vanishing point and followed line drawn: [`super::overlay`]) and `/`, the
//! live view (docs/http.md).
//!
//! Built on hyper (HTTP/1.1) over a tokio runtime confined to this service's thread: one
//! thread drives every connection concurrently, and a single blocking thread draws overlays,
//! so the pipeline's threads never run HTTP work. No client can block another: each
//! connection is its own task, a client must send its request head within
//! [`HttpOptions::header_timeout`] and in at most [`HttpOptions::max_header_bytes`], a
//! connection lives at most [`HttpOptions::connection_lifetime`], and at most
//! [`HttpOptions::max_connections`] are open at once (beyond that new ones are closed at
//! once). The service reads the node's [`crate::status`]; its threads run at nice 10, so
//! that serving and drawing use only the CPU time the pipeline leaves over.

use super::live::{History, StatusDocument};
use super::metrics::{metrics, TrackingCounts};
use crate::check::{Check, Raw};
use crate::source::SourceState;
use crate::status::{Latest, Shared};
use bytes::Bytes;
use http_body_util::Full;
use hyper::header::{HeaderValue, CACHE_CONTROL, CONTENT_TYPE};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;
use tokio::sync::{oneshot, Semaphore};

/// `[http]` of the node's configuration, as written.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHttp {
    enabled: Raw<bool>,
    listen: Raw<String>,
}

impl RawHttp {
    /// Checks `[http]`: the address to listen on, or None when the endpoint is disabled.
    pub(crate) fn validate(self, c: &mut Check) -> Option<SocketAddr> {
        if !c.get(&self.enabled, true) {
            return None;
        }
        match &self.listen {
            None => Some(SocketAddr::from(([127, 0, 0, 1], 8347))),
            Some(s) => c.addr("http.listen", s),
        }
    }
}

/// Draws the overlay of the latest frame and encodes it as PNG.
pub type OverlayFn = Arc<dyn Fn(&Latest) -> Result<Vec<u8>, String> + Send + Sync>;

/// The service's limits.
#[derive(Debug, Clone, PartialEq)]
pub struct HttpOptions {
    /// Connections open at once; a connection beyond this is closed without an answer.
    pub max_connections: usize,
    /// Time a client has to send a whole request head.
    pub header_timeout: Duration,
    /// Longest life of one connection (keep-alive included).
    pub connection_lifetime: Duration,
    /// Largest request head, bytes (hyper's read buffer; at least 8192).
    pub max_header_bytes: usize,
    /// Time between two samples of the latest estimate for `/history.json`.
    pub history_interval: Duration,
    /// How far back `/history.json` goes.
    pub history_window: Duration,
}

impl Default for HttpOptions {
    fn default() -> Self {
        HttpOptions {
            max_connections: 256,
            header_timeout: Duration::from_secs(5),
            connection_lifetime: Duration::from_secs(60),
            max_header_bytes: 16 * 1024,
            history_interval: Duration::from_millis(200),
            history_window: Duration::from_secs(60),
        }
    }
}

/// Errors starting the service.
#[derive(Debug, thiserror::Error)]
pub enum HttpError {
    #[error("binding {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("starting the HTTP runtime: {0}")]
    Runtime(std::io::Error),
}

/// The running HTTP service.
pub struct HttpServer {
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl HttpServer {
    /// Binds `addr` and serves with the default [`HttpOptions`] in a thread. `tracking` is
    /// what a [`super::metrics::TrackingCounter`] among the pipeline's publishers counts.
    pub fn start(
        addr: SocketAddr,
        shared: Arc<Shared>,
        overlay: OverlayFn,
        tracking: Arc<TrackingCounts>,
    ) -> Result<Self, HttpError> {
        Self::start_with(addr, shared, overlay, tracking, HttpOptions::default())
    }

    /// Binds `addr` and serves with `options` in a thread named `http`.
    pub fn start_with(
        addr: SocketAddr,
        shared: Arc<Shared>,
        overlay: OverlayFn,
        tracking: Arc<TrackingCounts>,
        options: HttpOptions,
    ) -> Result<Self, HttpError> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .max_blocking_threads(1)
            .thread_name("http-render")
            .on_thread_start(lower_priority)
            .build()
            .map_err(HttpError::Runtime)?;
        let bind = |source| HttpError::Bind { addr, source };
        let std_listener = std::net::TcpListener::bind(addr).map_err(bind)?;
        std_listener.set_nonblocking(true).map_err(bind)?;
        let listener = {
            let _guard = runtime.enter();
            tokio::net::TcpListener::from_std(std_listener).map_err(bind)?
        };
        let addr = listener.local_addr().map_err(bind)?;
        let (stop, stopped) = oneshot::channel();
        let service = Arc::new(Service::new(shared, overlay, tracking, &options));
        let thread = std::thread::Builder::new()
            .name("http".into())
            .spawn(move || {
                lower_priority();
                runtime.block_on(accept_loop(listener, service, options, stopped));
                // Connections still open are dropped; an overlay being drawn may finish.
                runtime.shutdown_timeout(Duration::from_secs(2));
            })
            .map_err(HttpError::Runtime)?;
        tracing::info!(%addr, "HTTP service: / /healthz /metrics /status /history.json /overlay.png");
        Ok(HttpServer {
            addr,
            stop: Some(stop),
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
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
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

/// Niceness of the service's threads: overlays are drawn (and requests answered) only with
/// CPU time the pipeline leaves over.
const NICE: libc::c_int = 10;

/// Lowers the calling thread's scheduling priority to [`NICE`] (Linux nices threads one by
/// one). A failure is logged: the service still works, only less politely.
fn lower_priority() {
    // SAFETY: setpriority reads its three integer arguments only; `who` 0 is the calling
    // thread on Linux.
    let rc = unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, NICE) };
    if rc != 0 {
        tracing::debug!(
            "HTTP: could not lower the thread's priority: {}",
            std::io::Error::last_os_error()
        );
    }
}

async fn accept_loop(
    listener: tokio::net::TcpListener,
    service: Arc<Service>,
    options: HttpOptions,
    mut stopped: oneshot::Receiver<()>,
) {
    tokio::spawn(sample_history(service.clone(), options.history_interval));
    let slots = Arc::new(Semaphore::new(options.max_connections));
    loop {
        let (stream, peer) = tokio::select! {
            _ = &mut stopped => return,
            accepted = listener.accept() => match accepted {
                Ok(c) => c,
                Err(e) => {
                    // E.g. out of file descriptors: wait rather than spin.
                    tracing::warn!("HTTP accept: {e}");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::debug!(%peer, max = options.max_connections, "HTTP: too many connections, closing");
            continue;
        };
        let _ = stream.set_nodelay(true);
        let service = service.clone();
        let options = options.clone();
        tokio::spawn(async move {
            let handler = hyper::service::service_fn(move |req| {
                let service = service.clone();
                async move { Ok::<_, Infallible>(service.handle(req).await) }
            });
            let conn = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(options.header_timeout)
                .max_buf_size(options.max_header_bytes.max(8192))
                .serve_connection(TokioIo::new(stream), handler);
            match tokio::time::timeout(options.connection_lifetime, conn).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => tracing::debug!(%peer, "HTTP: {e}"),
                Err(_) => tracing::debug!(%peer, "HTTP: connection lifetime reached"),
            }
            drop(slot);
        });
    }
}

/// Samples the latest estimate into the history.
async fn sample_history(service: Arc<Service>, every: Duration) {
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        service.history.sample(&service.shared);
    }
}

type Body = Full<Bytes>;

/// What the handlers share.
struct Service {
    shared: Arc<Shared>,
    overlay: OverlayFn,
    tracking: Arc<TrackingCounts>,
    history: History,
    /// The PNG of the latest frame drawn so far (sequence number, bytes): one drawing per
    /// frame however many clients ask, and one at a time.
    overlay_cache: tokio::sync::Mutex<Option<(u64, Bytes)>>,
}

impl Service {
    fn new(
        shared: Arc<Shared>,
        overlay: OverlayFn,
        tracking: Arc<TrackingCounts>,
        options: &HttpOptions,
    ) -> Self {
        Service {
            shared,
            overlay,
            tracking,
            history: History::new(options.history_window),
            overlay_cache: tokio::sync::Mutex::new(None),
        }
    }

    async fn handle(&self, req: Request<hyper::body::Incoming>) -> Response<Body> {
        if req.method() != Method::GET && req.method() != Method::HEAD {
            return text(StatusCode::METHOD_NOT_ALLOWED, "only GET and HEAD\n");
        }
        match req.uri().path() {
            "/" => respond(
                StatusCode::OK,
                "text/html; charset=utf-8",
                Bytes::from_static(super::live::PAGE.as_bytes()),
            ),
            "/healthz" => self.healthz(),
            "/metrics" => respond(
                StatusCode::OK,
                "text/plain; version=0.0.4; charset=utf-8",
                Bytes::from(metrics(&self.shared, &self.tracking)),
            ),
            "/status" => json(&StatusDocument::now(&self.shared)),
            "/history.json" => json(&self.history.document()),
            "/overlay.png" => self.overlay().await,
            _ => text(StatusCode::NOT_FOUND, "not found\n"),
        }
    }

    fn healthz(&self) -> Response<Body> {
        let alive = self.shared.alive();
        let state = self.shared.source_state();
        let ok = alive && matches!(state, SourceState::Streaming | SourceState::Starting);
        let body = serde_json::json!({
            "healthy": ok,
            "pipeline_alive": alive,
            "source": state.name(),
            "frames_in": self.shared.frames_in(),
            // Detection is what health means; the recording's state is said alongside.
            "recording": self.shared.status().recording,
        });
        let code = if ok {
            StatusCode::OK
        } else {
            StatusCode::SERVICE_UNAVAILABLE
        };
        respond(code, "application/json", Bytes::from(format!("{body}\n")))
    }

    async fn overlay(&self) -> Response<Body> {
        let Some(latest) = self.shared.latest() else {
            return text(StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n");
        };
        let seq = latest.frame.seq;
        let mut cache = self.overlay_cache.lock().await;
        if let Some((s, png)) = cache.as_ref() {
            if *s == seq {
                return respond(StatusCode::OK, "image/png", png.clone());
            }
        }
        let draw = self.overlay.clone();
        match tokio::task::spawn_blocking(move || draw(&latest)).await {
            Ok(Ok(png)) => {
                let png = Bytes::from(png);
                *cache = Some((seq, png.clone()));
                respond(StatusCode::OK, "image/png", png)
            }
            Ok(Err(e)) => text(
                StatusCode::INTERNAL_SERVER_ERROR,
                &format!("overlay of frame {seq}: {e}\n"),
            ),
            Err(e) => text(
                StatusCode::INTERNAL_SERVER_ERROR,
                &format!("overlay of frame {seq}: the drawing thread failed: {e}\n"),
            ),
        }
    }
}

fn respond(code: StatusCode, content_type: &'static str, body: Bytes) -> Response<Body> {
    let mut r = Response::new(Full::new(body));
    *r.status_mut() = code;
    let h = r.headers_mut();
    h.insert(CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

fn text(code: StatusCode, body: &str) -> Response<Body> {
    respond(
        code,
        "text/plain; charset=utf-8",
        Bytes::from(body.to_owned()),
    )
}

fn json(value: &impl serde::Serialize) -> Response<Body> {
    match serde_json::to_vec(value) {
        Ok(mut body) => {
            body.push(b'\n');
            respond(StatusCode::OK, "application/json", Bytes::from(body))
        }
        Err(e) => text(
            StatusCode::INTERNAL_SERVER_ERROR,
            &format!("encoding JSON: {e}\n"),
        ),
    }
}
