//! The acquisition thread: connect, stream, detect loss, reconnect — for as long as it runs.
//!
//! One thread owns every Aravis object. It opens and configures the camera, creates the
//! stream with its preallocated buffers, and pops buffers with a timeout. A complete buffer
//! is copied into a recycled `Vec<u8>` (see [`super::pool`]), handed to the sink as a
//! [`Frame`], and goes straight back to the stream; an incomplete one (missing packets,
//! timeout, size mismatch, ...) is counted and goes straight back without reaching the sink.
//! Aravis's control-lost signal, or `lost_after_timeouts` consecutive pop timeouts, mark the
//! camera lost; the thread then tears the session down and reopens the camera with the same
//! configuration, with exponential backoff, until it answers again or the owner stops it.

use super::clock::{CameraClock, CameraClockOptions};
use super::config::GigeConfig;
use super::counters::{CameraState, GigeCounters};
use super::device::{configure, create_stream, open_camera, SessionInfo};
use super::pool::{FramePool, Recycler, Taken};
use super::GigeError;
use crate::frame::{now_ns, Frame};
use aravis::prelude::*;
use aravis::{BufferPayloadType, BufferStatus, Camera, Stream};
use crossbeam_channel::{Sender, TrySendError};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Where complete frames go.
pub enum FrameSink {
    /// `try_send`: when the channel is full the frame is dropped (counted in `dropped`) and
    /// its buffer recycled; when the receiver is gone, acquisition stops.
    Channel(Sender<Frame>),
    /// Called on the acquisition thread for each complete frame; keep it short. Returning
    /// false stops acquisition.
    Callback(Box<dyn FnMut(Frame) -> bool + Send>),
}

/// Called on the acquisition thread after each successful open and configuration, before
/// streaming starts (e.g. to set up Aravis's in-process fake camera in tests).
pub type OnConnect = Box<dyn Fn(&Camera) + Send>;

/// A running acquisition. Dropping it stops the thread.
pub struct GigeSource {
    stop: Arc<AtomicBool>,
    counters: Arc<GigeCounters>,
    session: Arc<Mutex<Option<SessionInfo>>>,
    recycler: Recycler,
    thread: Option<JoinHandle<()>>,
}

/// Longest single wait in a pop, so that a stop request is seen quickly.
const POP_SLICE: Duration = Duration::from_millis(100);

impl GigeSource {
    /// Validates the configuration and starts the acquisition thread. Never fails because
    /// the camera is absent: the thread keeps trying (state `connecting`, then
    /// `camera_lost` after a loss).
    pub fn start(cfg: GigeConfig, sink: FrameSink) -> Result<Self, GigeError> {
        Self::start_with(cfg, sink, None)
    }

    /// [`GigeSource::start`] with a hook run after each (re)connection.
    pub fn start_with(
        cfg: GigeConfig,
        sink: FrameSink,
        on_connect: Option<OnConnect>,
    ) -> Result<Self, GigeError> {
        cfg.validate()?;
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(GigeCounters::new());
        let session = Arc::new(Mutex::new(None));
        let pool = FramePool::new(cfg.buffers as usize * 2);
        let recycler = pool.recycler();
        let worker = Worker {
            cfg,
            sink,
            on_connect,
            stop: stop.clone(),
            counters: counters.clone(),
            session: session.clone(),
            pool,
            clock: CameraClock::new(CameraClockOptions::default()),
            seq: 0,
        };
        let thread = std::thread::Builder::new()
            .name("omnirow-gige".into())
            .spawn(move || worker.run())
            .map_err(GigeError::Spawn)?;
        Ok(GigeSource {
            stop,
            counters,
            session,
            recycler,
            thread: Some(thread),
        })
    }

    /// The live counters and state.
    pub fn counters(&self) -> Arc<GigeCounters> {
        self.counters.clone()
    }

    /// Where consumers return `frame.data` for reuse.
    pub fn recycler(&self) -> Recycler {
        self.recycler.clone()
    }

    /// What the camera was set to in the current (or last) session.
    pub fn session(&self) -> Option<SessionInfo> {
        self.session.lock().ok().and_then(|s| s.clone())
    }

    /// Whether the thread is still running (it ends only on stop or when the sink is gone).
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops the thread and waits for it (at most one pop slice plus the camera's teardown).
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                tracing::error!("the acquisition thread panicked");
            }
        }
        self.counters.set_state(CameraState::Stopped);
    }
}

impl Drop for GigeSource {
    fn drop(&mut self) {
        self.shutdown();
    }
}

struct Worker {
    cfg: GigeConfig,
    sink: FrameSink,
    on_connect: Option<OnConnect>,
    stop: Arc<AtomicBool>,
    counters: Arc<GigeCounters>,
    session: Arc<Mutex<Option<SessionInfo>>>,
    pool: FramePool,
    clock: CameraClock,
    seq: u64,
}

/// Why a streaming session ended.
enum SessionEnd {
    Stopped,
    SinkGone,
    Lost(&'static str),
}

impl Worker {
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    fn run(mut self) {
        if self.cfg.realtime {
            super::rt::make_current_thread_realtime("omnirow-gige", self.cfg.realtime_priority);
        } else {
            tracing::info!(
                thread = "omnirow-gige",
                "real-time priority not requested (gige.realtime = false)"
            );
        }
        let mut backoff = Duration::from_millis(self.cfg.reconnect_initial_ms);
        let max_backoff = Duration::from_millis(self.cfg.reconnect_max_ms);
        let mut ever_connected = false;
        while !self.stopping() {
            match self.connect() {
                Ok((camera, stream, info)) => {
                    if ever_connected {
                        GigeCounters::bump(&self.counters.reconnects);
                        tracing::info!(camera = %info.serial, "camera back; streaming resumes with the same configuration");
                    }
                    ever_connected = true;
                    backoff = Duration::from_millis(self.cfg.reconnect_initial_ms);
                    let end = self.stream(&camera, &stream, &info);
                    if let SessionEnd::Lost(_) = end {
                        // Say so before the teardown, which waits on a camera that is gone.
                        self.counters.set_state(CameraState::CameraLost);
                    }
                    // Teardown: errors are expected when the camera is gone.
                    let t = Instant::now();
                    let _ = camera.stop_acquisition();
                    drop(stream);
                    drop(camera);
                    tracing::debug!(ms = t.elapsed().as_millis() as u64, "session torn down");
                    match end {
                        SessionEnd::Stopped => break,
                        SessionEnd::SinkGone => {
                            tracing::info!("frame consumer gone; acquisition ends");
                            break;
                        }
                        SessionEnd::Lost(why) => {
                            tracing::warn!(reason = why, "camera lost; reconnecting");
                        }
                    }
                }
                Err(e) => {
                    GigeCounters::bump(&self.counters.connect_failures);
                    if ever_connected {
                        self.counters.set_state(CameraState::CameraLost);
                    }
                    tracing::warn!(error = %e, retry_in_ms = backoff.as_millis() as u64, "camera not available");
                    self.sleep(backoff);
                    backoff = (backoff * 2).min(max_backoff);
                }
            }
        }
        self.counters.set_state(CameraState::Stopped);
    }

    /// Sleeps in short slices so that a stop request ends it early.
    fn sleep(&self, d: Duration) {
        let end = Instant::now() + d;
        while !self.stopping() {
            let now = Instant::now();
            if now >= end {
                break;
            }
            std::thread::sleep((end - now).min(POP_SLICE));
        }
    }

    fn connect(&mut self) -> Result<(Camera, Stream, SessionInfo), GigeError> {
        let camera = open_camera(self.cfg.camera.as_deref())?;
        let info = configure(&camera, &self.cfg)?;
        if let Some(hook) = &self.on_connect {
            hook(&camera);
        }
        let stream = create_stream(&camera, &self.cfg, info.payload_bytes)?;
        camera
            .set_acquisition_mode(aravis::AcquisitionMode::Continuous)
            .map_err(|e| GigeError::Aravis {
                what: "setting AcquisitionMode=Continuous".into(),
                message: e.to_string(),
            })?;
        camera.start_acquisition().map_err(|e| GigeError::Aravis {
            what: "starting acquisition".into(),
            message: e.to_string(),
        })?;
        tracing::info!(
            vendor = %info.vendor, model = %info.model, serial = %info.serial,
            width = info.width, height = info.height, pixel_format = %info.pixel_format,
            frame_rate = ?info.frame_rate, packet_size = ?info.packet_size,
            payload = info.payload_bytes, buffers = self.cfg.buffers,
            "camera streaming"
        );
        if let Ok(mut s) = self.session.lock() {
            *s = Some(info.clone());
        }
        Ok((camera, stream, info))
    }

    fn note_stream_buffers(&self, stream: &Stream) {
        let (n_in, n_out) = stream.n_buffers();
        self.counters
            .stream_buffers
            .store((n_in.max(0) + n_out.max(0)) as u64, Ordering::Relaxed);
    }

    fn stream(&mut self, camera: &Camera, stream: &Stream, info: &SessionInfo) -> SessionEnd {
        let lost = Arc::new(AtomicBool::new(false));
        let _handler = camera.device().map(|d| {
            let lost = lost.clone();
            d.connect_control_lost(move |_| {
                lost.store(true, Ordering::Release);
            })
        });
        self.clock.reset();
        let format = self.cfg.pixel_format.frame_format();
        let expect_fmt = match self.cfg.pixel_format {
            super::GigePixelFormat::BayerRG8 => aravis::PixelFormat::BAYER_RG_8,
            super::GigePixelFormat::Mono8 => aravis::PixelFormat::MONO_8,
        };
        let frame_len = info.width as usize * info.height as usize * format.bytes_per_pixel();
        let pop_timeout = self.cfg.effective_pop_timeout();
        let mut consecutive_timeouts = 0u32;
        let mut waited = Duration::ZERO;
        let mut last_block_id: Option<u64> = None;
        loop {
            if self.stopping() {
                return SessionEnd::Stopped;
            }
            if lost.load(Ordering::Acquire) {
                return SessionEnd::Lost("control lost (heartbeat)");
            }
            let slice = POP_SLICE.min(pop_timeout);
            let Some(buffer) = stream.timeout_pop_buffer(slice.as_micros() as u64) else {
                waited += slice;
                if waited >= pop_timeout {
                    waited = Duration::ZERO;
                    GigeCounters::bump(&self.counters.timeouts);
                    consecutive_timeouts += 1;
                    tracing::debug!(consecutive_timeouts, "no frame within the pop timeout");
                    if consecutive_timeouts >= self.cfg.lost_after_timeouts {
                        return SessionEnd::Lost("no frames (pop timeouts)");
                    }
                }
                continue;
            };
            waited = Duration::ZERO;
            consecutive_timeouts = 0;
            if self.counters.state() != CameraState::Streaming {
                self.counters.set_state(CameraState::Streaming);
            }
            let receive_ns = now_ns();
            // seq follows the camera's block ids, so gaps are frames lost upstream.
            let fid = buffer.frame_id();
            let step = match last_block_id {
                Some(last) => super::block_id_step(last, fid),
                None => 1,
            };
            last_block_id = Some(fid);
            if step > 1 {
                self.counters.missing.fetch_add(step - 1, Ordering::Relaxed);
            }
            self.seq += step;
            let status = buffer.status();
            let (ptr, len) = buffer.data();
            let ok = status == BufferStatus::Success
                && buffer.payload_type() == BufferPayloadType::Image
                && buffer.image_pixel_format() == expect_fmt
                && buffer.image_width() as u32 == info.width
                && buffer.image_height() as u32 == info.height
                && !ptr.is_null()
                && len >= frame_len;
            if !ok {
                GigeCounters::bump(&self.counters.incomplete);
                tracing::debug!(
                    ?status,
                    payload = ?buffer.payload_type(),
                    width = buffer.image_width(),
                    height = buffer.image_height(),
                    len,
                    "incomplete frame dropped"
                );
                stream.push_buffer(buffer);
                self.note_stream_buffers(stream);
                continue;
            }
            let (mut data, taken) = self.pool.take(frame_len);
            if taken == Taken::Allocated {
                GigeCounters::bump(&self.counters.frame_allocations);
            }
            // SAFETY: Aravis owns `len` valid bytes at `ptr` while we hold `buffer` (it is
            // out of the stream until pushed back below); frame_len <= len was checked.
            data.copy_from_slice(unsafe { std::slice::from_raw_parts(ptr, frame_len) });
            let host_ns = match buffer.system_timestamp() {
                0 => receive_ns,
                t => t,
            };
            let capture_ns = self.clock.capture_ns(buffer.timestamp(), host_ns);
            stream.push_buffer(buffer);
            self.note_stream_buffers(stream);
            let frame = Frame {
                seq: self.seq,
                capture_ns,
                receive_ns,
                width: info.width,
                height: info.height,
                format,
                data,
                truth: None,
            };
            GigeCounters::bump(&self.counters.received);
            match &mut self.sink {
                FrameSink::Channel(tx) => match tx.try_send(frame) {
                    Ok(()) => {}
                    Err(TrySendError::Full(f)) => {
                        GigeCounters::bump(&self.counters.dropped);
                        self.pool.give_back(f.data);
                    }
                    Err(TrySendError::Disconnected(_)) => return SessionEnd::SinkGone,
                },
                FrameSink::Callback(f) => {
                    if !f(frame) {
                        return SessionEnd::SinkGone;
                    }
                }
            }
        }
    }
}
