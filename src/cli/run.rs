//! `omnirow run` (the node) and `omnirow record` (the node, recording).
//!
//! Owns assembling the node from its configuration — source, calibration, detector workers,
//! publishers, recorder, HTTP endpoint — and its life as a daemon: systemd notifications
//! (READY once frames flow, WATCHDOG only while the pipeline is alive, STATUS once a second,
//! STOPPING on shutdown) and SIGTERM/SIGINT handling. Signals go through `signal-hook`'s
//! flag registration: it sets an `AtomicBool` from an async-signal-safe handler, keeps
//! `unsafe` out of this crate, and its `register_conditional_shutdown` makes a second signal
//! exit at once; the main loop polls the flag every 20 ms.

use crate::camera::{Calibration, IdealLens};
use crate::config::Config;
use crate::guidance::Guidance;
use crate::notify::Notifier;
use crate::perception::Measurement;
use crate::pipeline::{Pipeline, Processor};
use crate::publish::http::{HttpServer, OverlayFn};
use crate::publish::metrics::{TrackingCounter, TrackingCounts};
use crate::publish::overlay::overlay_png;
use crate::publish::stdout::{StdoutMode, StdoutPublisher};
use crate::publish::udp::{UdpOptions, UdpPublisher};
use crate::publish::Publisher;
use crate::record::Recorder;
use crate::source::folder::{FolderOptions, FolderReplay};
use crate::source::mcap_replay::{McapReplay, McapReplayOptions};
use crate::source::synthetic::{SyntheticConfig, SyntheticDrive};
use crate::source::{CalibrationChoice, Rate, ReplayConfig, Source, SourceConfig, SourceState};
use crate::status::Latest;
use anyhow::{bail, Context};
use clap::Args;
use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Options of `omnirow run` (they override the configuration file).
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Configuration file (config/omnirow.toml documents it). Without one: the built-in
    /// defaults, i.e. the synthetic drive.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Stop after N frames.
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Print estimates as JSON lines on stdout (the default when stdout is a terminal).
    #[arg(long, conflicts_with = "no_print")]
    pub print: bool,
    /// Never print estimates on stdout.
    #[arg(long)]
    pub no_print: bool,
    /// Replay this MCAP file or image folder instead of the configured source.
    #[arg(long, value_name = "PATH")]
    pub replay: Option<PathBuf>,
    /// Replay rate: `recorded`, `max` (as fast as possible), or a multiple of the recorded
    /// rate such as `2`.
    #[arg(long, value_name = "RATE")]
    pub rate: Option<String>,
    /// Replay in a loop.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Send estimates to this UDP destination (repeatable; replaces the configured ones).
    #[arg(long, value_name = "ADDR:PORT")]
    pub udp: Vec<SocketAddr>,
    /// HTTP listen address, or `off`.
    #[arg(long, value_name = "ADDR:PORT")]
    pub http: Option<String>,
    /// Calibration: `ideal:fisheye185`, `ideal:pal`, or a file (the synthetic drive renders
    /// through it).
    #[arg(long, value_name = "CALIB")]
    pub calib: Option<String>,
    /// Detector worker threads.
    #[arg(long, value_name = "N")]
    pub workers: Option<usize>,
    /// Frame queue capacity between the source and the detector.
    #[arg(long, value_name = "N")]
    pub frame_queue: Option<usize>,
}

/// Loads the configuration and applies the command-line overrides.
fn configure(args: &RunArgs) -> anyhow::Result<Config> {
    let mut cfg = match &args.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    if let Some(n) = args.frames {
        cfg.pipeline.max_frames = Some(n);
    }
    if let Some(s) = args.duration {
        if !(s > 0.0 && s.is_finite()) {
            bail!("--duration must be a positive number of seconds");
        }
        cfg.pipeline.max_duration = Some(Duration::from_secs_f64(s));
    }
    if let Some(path) = &args.replay {
        let (rate, looping, topic, fps) = match &cfg.source {
            SourceConfig::Replay(r) => (r.rate, r.looping, r.topic.clone(), r.fps),
            _ => (Rate::Recorded(1.0), false, None, 15.0),
        };
        cfg.source = SourceConfig::Replay(ReplayConfig {
            path: path.clone(),
            rate,
            looping,
            topic,
            fps,
        });
    }
    if let SourceConfig::Replay(r) = &mut cfg.source {
        if let Some(rate) = &args.rate {
            r.rate = match rate.as_str() {
                "recorded" => Rate::Recorded(1.0),
                "max" => Rate::Max,
                x => match x.parse::<f64>() {
                    Ok(v) if v > 0.0 && v.is_finite() => Rate::Recorded(v),
                    _ => bail!("--rate {x}: expected `recorded`, `max` or a positive multiple"),
                },
            };
        }
        r.looping |= args.looping;
    } else if args.rate.is_some() || args.looping {
        bail!("--rate and --loop apply to replays (--replay PATH or [source] kind = \"replay\")");
    }
    if !args.udp.is_empty() {
        cfg.udp = args.udp.clone();
    }
    if let Some(h) = &args.http {
        cfg.http = if h == "off" {
            None
        } else {
            Some(
                h.parse()
                    .with_context(|| format!("--http {h}: expected ADDR:PORT or off"))?,
            )
        };
    }
    if let Some(c) = &args.calib {
        cfg.calibration = match c.as_str() {
            "ideal:fisheye185" => CalibrationChoice::Ideal(IdealLens::Fisheye185),
            "ideal:pal" => CalibrationChoice::Ideal(IdealLens::Pal),
            "auto" => CalibrationChoice::Auto,
            p => CalibrationChoice::File(PathBuf::from(p)),
        };
    }
    if let Some(w) = args.workers {
        if !(1..=8).contains(&w) {
            bail!("--workers must be 1..=8");
        }
        cfg.workers = w;
    }
    if let Some(q) = args.frame_queue {
        if !(1..=64).contains(&q) {
            bail!("--frame-queue must be 1..=64");
        }
        cfg.pipeline.frame_queue = q;
    }
    if args.print {
        cfg.stdout = StdoutMode::Always;
    }
    if args.no_print {
        cfg.stdout = StdoutMode::Never;
    }
    Ok(cfg)
}

/// The GigE Vision camera of `[gige]` (`[source] kind = "camera"`).
#[cfg(feature = "camera")]
fn camera_source(g: &crate::gige::GigeConfig) -> anyhow::Result<Box<dyn Source>> {
    // One frame may wait between the acquisition thread and the pipeline's own queue.
    let cam = crate::source::gige::CameraSource::start(g.clone(), 1).context("[gige] camera")?;
    Ok(Box::new(cam))
}

#[cfg(not(feature = "camera"))]
fn camera_source(_: &crate::gige::GigeConfig) -> anyhow::Result<Box<dyn Source>> {
    bail!(
        "[source] kind = \"camera\": this omnirow was built without the `camera` feature \
         (libaravis); build it with `cargo build --release --features camera` (README: Camera)"
    )
}

/// The synthetic drive of `[source.synthetic]`, rendered through `[camera] calibration`: a
/// file at its own size, or rescaled to the drive's `width`×`height` when they are written;
/// an ideal lens at the drive's size; `auto`, the drive's `lens`. Over its photograph's
/// ground when it names one (read now: an unreadable or unfit photograph is an error before
/// anything starts).
fn synthetic_source(
    s: &SyntheticConfig,
    choice: &CalibrationChoice,
) -> anyhow::Result<SyntheticDrive> {
    let mut opts = s.drive.clone();
    let drive = match choice {
        CalibrationChoice::File(p) => {
            let cal = Calibration::load(p)
                .with_context(|| format!("camera.calibration {}", p.display()))?;
            let cal = if s.size_given {
                let (h, w) = (opts.height, opts.width);
                cal.rescaled_to(h, w).map_err(|e| {
                    anyhow::anyhow!(
                        "source.synthetic.width = {w}, height = {h} through camera.calibration {}: \
                         {e}; without both keys the drive renders at the calibration's size",
                        p.display()
                    )
                })?
            } else {
                cal
            };
            SyntheticDrive::through(opts, cal)
        }
        CalibrationChoice::Ideal(lens) => {
            opts.lens = *lens;
            SyntheticDrive::new(opts)
        }
        CalibrationChoice::Auto => SyntheticDrive::new(opts),
    }
    .context("synthetic drive")?;
    let Some(photo) = &s.photo else {
        return Ok(drive);
    };
    let ground =
        super::synth::photo::ground_of_photograph(&photo.image, &photo.labels, &photo.options)
            .context("source.synthetic.photo")?;
    drive.with_photo_ground(Arc::new(ground)).with_context(|| {
        format!(
            "source.synthetic.photo: the ground of {}",
            photo.image.display()
        )
    })
}

/// The calibration the detector uses: the synthetic drive's own (it renders through the
/// configured one), else `[camera] calibration`, else the source's (a recording's), else the
/// ideal fisheye at the frames' size.
fn detector_calibration(cfg: &Config, source: &dyn Source) -> anyhow::Result<Calibration> {
    if let (SourceConfig::Synthetic(_), Some(c)) = (&cfg.source, source.calibration()) {
        return Ok(c.clone());
    }
    Ok(match &cfg.calibration {
        CalibrationChoice::File(p) => Calibration::load(p)?,
        CalibrationChoice::Ideal(l) => l.calibration(2050, 2448)?,
        CalibrationChoice::Auto => match source.calibration() {
            Some(c) => c.clone(),
            None => {
                // A camera's region of interest sets the frame size; otherwise the GC2450C's.
                let (h, w) = match &cfg.source {
                    SourceConfig::Camera(g) => g.roi.map_or((2050, 2448), |r| (r.height, r.width)),
                    _ => (2050, 2448),
                };
                tracing::warn!("no calibration configured or recorded: using the ideal 185° fisheye at {w}x{h} (camera.calibration)");
                IdealLens::Fisheye185.calibration(h, w).map_err(|e| {
                    anyhow::anyhow!(
                        "camera.calibration: no calibration for the {w}x{h} frames: {e}"
                    )
                })?
            }
        },
    })
}

/// Each stage's time ([`crate::estimate::STAGES`]) as one line: `prepare 3.10, rows ...`.
fn stage_line(ms: &[f64; 4]) -> String {
    let parts: Vec<String> = crate::estimate::STAGES
        .iter()
        .zip(ms)
        .map(|(name, v)| format!("{name} {v:.2}"))
        .collect();
    parts.join(", ")
}

/// `omnirow run` and `omnirow record --out DIR`.
pub fn run(args: RunArgs, record_to: Option<PathBuf>) -> anyhow::Result<ExitCode> {
    let mut cfg = configure(&args)?;
    if let Some(dir) = record_to {
        let mut rec = cfg.record_options.clone();
        rec.dir = dir;
        rec.frame_id = cfg.frame_id.clone();
        cfg.record = Some(rec);
    }
    crate::logging::init(cfg.log_format, &cfg.log_level);

    // Source (opened now, so a missing file is an error before anything starts).
    let source: Box<dyn Source> = match &cfg.source {
        SourceConfig::Synthetic(s) => Box::new(synthetic_source(s, &cfg.calibration)?),
        SourceConfig::Replay(r) if r.path.is_dir() => {
            Box::new(FolderReplay::open(FolderOptions {
                dir: r.path.clone(),
                fps: r.fps,
                rate: r.rate,
                looping: r.looping,
            })?)
        }
        SourceConfig::Replay(r) => Box::new(McapReplay::open(McapReplayOptions {
            path: r.path.clone(),
            rate: r.rate,
            looping: r.looping,
            topic: r.topic.clone(),
        })?),
        SourceConfig::Camera(g) => camera_source(g)?,
    };
    let cal = detector_calibration(&cfg, source.as_ref())?;
    if let Some(rec) = cfg.record.as_mut() {
        rec.calibration_toml = Some(cal.to_toml());
        rec.annotate = Some(cal.clone());
    }
    // Odometry from ROS 2 for guidance's motion model, when both are on.
    let odometry =
        (cfg.guidance.is_some() && cfg.ros2.enabled && cfg.ros2.odometry_topic_name().is_some())
            .then(|| Arc::new(crate::guidance::OdometryFeed::new()));
    if let Some(g) = cfg.guidance {
        let mut g = Guidance::new(g, cal.mounting).context("[guidance] (docs/guidance.md)")?;
        if let Some(feed) = &odometry {
            g = g.with_odometry_feed(feed.clone());
        }
        cfg.pipeline.guidance = Some(g);
    }
    if let Some(n) = cfg.pipeline.narrow_search.as_mut() {
        n.mounting = cal.mounting;
    }

    // Detector workers.
    let opts = cfg.detector.clone();
    let mut processors: Vec<Box<dyn Processor>> = Vec::new();
    for w in 0..cfg.workers {
        processors.push(Box::new(
            Measurement::new(
                &cal,
                opts.clone(),
                cfg.threads,
                cfg.pipeline.pin_threads.then_some(w * cfg.threads),
                cfg.guidance.is_some(),
                cfg.pipeline.min_quality,
            )
            .context("detector")?,
        ));
    }

    // Publishers.
    let mut publishers: Vec<Box<dyn Publisher>> = Vec::new();
    if !cfg.udp.is_empty() {
        publishers.push(Box::new(UdpPublisher::new(&UdpOptions {
            destinations: cfg.udp.clone(),
            multicast_ttl: cfg.multicast_ttl,
            multicast_loop: cfg.multicast_loop,
            multicast_interface: cfg.multicast_interface,
        })?));
        tracing::info!(destinations = ?cfg.udp, "publishing estimates over UDP");
    }
    let print = match cfg.stdout {
        StdoutMode::Always => true,
        StdoutMode::Never => false,
        StdoutMode::Auto => std::io::stdout().is_terminal(),
    };
    if print {
        publishers.push(Box::new(StdoutPublisher::new()));
    }
    let tool_point_m = cfg.guidance.map_or([0.0; 2], |g| g.tool_point_m);
    if let Some(p) =
        crate::ros2::node_publisher(&cfg.ros2, &source.describe(), tool_point_m, odometry)
            .context("[ros2] publisher (docs/ros2.md)")?
    {
        tracing::info!(
            namespace = %cfg.ros2.namespace,
            node = %cfg.ros2.node_name,
            "publishing on ROS 2"
        );
        publishers.push(p);
    }

    // The guidance's tracking-state changes for /metrics, counted on every estimate.
    let tracking_counts = Arc::new(TrackingCounts::default());
    if cfg.http.is_some() {
        publishers.push(Box::new(TrackingCounter(tracking_counts.clone())));
    }

    // A recording that cannot start does not stop detection: the node runs, says so on
    // /healthz and /metrics, and exits non-zero at the end.
    let recorder = cfg.record.as_ref().map(|r| {
        Recorder::new(r.clone()).unwrap_or_else(|e| {
            tracing::error!("recording not started: {e}; detection goes on");
            Recorder::failed(r.clone(), e.to_string())
        })
    });
    let record_health = recorder.as_ref().map(Recorder::health);

    // Signals before threads start, so none is missed.
    let term = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        // A second signal while the first is being handled exits at once (code 1).
        signal_hook::flag::register_conditional_shutdown(sig, 1, term.clone())
            .context("installing the signal handler")?;
        signal_hook::flag::register(sig, term.clone()).context("installing the signal handler")?;
    }

    let notifier = Notifier::from_env()?;
    let pipeline = Pipeline::start(
        source,
        processors,
        publishers,
        recorder,
        cfg.pipeline.clone(),
    )?;
    let shared = pipeline.shared();

    let http = match cfg.http {
        Some(addr) => {
            let overlay_cal = cal.clone();
            let overlay: OverlayFn = Arc::new(move |l: &Latest| overlay_png(&overlay_cal, l));
            // The estimates matter more than the endpoint: a busy port is a loud warning,
            // not a node that will not start.
            match HttpServer::start(addr, shared.clone(), overlay, tracking_counts) {
                Ok(h) => Some(h),
                Err(e) => {
                    tracing::error!(%addr, "HTTP endpoint not started: {e} (http.listen)");
                    None
                }
            }
        }
        None => None,
    };

    // Supervision: systemd notifications and signals.
    let watchdog_every = notifier.watchdog_interval();
    let mut ready = false;
    let mut stopping = false;
    let mut last_watchdog: Option<Instant> = None;
    let mut last_status = Instant::now();
    let mut was_alive = true;
    while !pipeline.is_finished() {
        std::thread::sleep(Duration::from_millis(20));
        if term.load(Ordering::Relaxed) && !stopping {
            stopping = true;
            tracing::info!("signal received: stopping the source, draining the pipeline");
            notifier.stopping("stopping: draining the pipeline");
            pipeline.request_stop();
        }
        // Ready once frames flow, or once the camera is known to be absent: the node is then
        // doing its job (publishing camera_lost, reconnecting), and systemd must not kill it
        // for a slow start.
        if !ready && shared.frames_in() > 0 {
            ready = true;
            notifier.ready("streaming: first frames received");
        } else if !ready && shared.source_state() == SourceState::Lost {
            ready = true;
            notifier.ready("camera_lost: no camera yet, reconnecting");
        }
        let alive = shared.alive();
        if alive != was_alive {
            if alive {
                tracing::info!("pipeline alive again");
            } else {
                tracing::error!(stuck = ?shared.stuck_threads(), "pipeline stuck: systemd watchdog no longer fed");
            }
            was_alive = alive;
        }
        if let Some(every) = watchdog_every {
            if alive && last_watchdog.is_none_or(|t| t.elapsed() >= every) {
                notifier.watchdog();
                last_watchdog = Some(Instant::now());
            }
        }
        if last_status.elapsed() >= cfg.pipeline.status_interval && !stopping {
            last_status = Instant::now();
            let st = shared.status();
            notifier.status(&format!(
                "{}: {:.1} fps, {} in, {} out, {} dropped, detector p99 {:.1} ms, {}",
                st.source_state.name(),
                st.fps_out,
                st.frames_in,
                st.frames_out,
                st.dropped,
                st.detector_p99_ms,
                st.recording
            ));
        }
    }
    if !stopping {
        notifier.stopping("stopping: source ended");
    }
    let st = pipeline.join().map_err(anyhow::Error::msg)?;
    if let Some(h) = http {
        h.stop();
    }
    tracing::info!(
        frames_in = st.frames_in,
        frames_out = st.frames_out,
        dropped = st.dropped,
        record_dropped = st.record_dropped,
        recorded_frames = st.recorded_frames,
        detector_p50_ms = format_args!("{:.2}", st.detector_p50_ms),
        detector_p99_ms = format_args!("{:.2}", st.detector_p99_ms),
        latency_p50_ms = format_args!("{:.2}", st.latency_p50_ms),
        latency_p99_ms = format_args!("{:.2}", st.latency_p99_ms),
        stage_p50_ms = %stage_line(&st.stage_p50_ms),
        stage_p99_ms = %stage_line(&st.stage_p99_ms),
        "finished"
    );
    if let Some(e) = shared.source_error() {
        bail!("source failed: {e}");
    }
    if st.source_state == SourceState::Lost && !stopping {
        bail!("the camera was lost");
    }
    if let Some(why) = record_health.and_then(|h| h.failure()) {
        bail!(
            "the recording {why}; {} frames recorded",
            st.recorded_frames
        );
    }
    Ok(ExitCode::SUCCESS)
}
