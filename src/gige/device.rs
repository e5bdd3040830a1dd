//! Finding, opening and configuring a camera through Aravis, and creating its stream.
//!
//! Owns everything that touches Aravis objects before frames flow: the camera list, matching
//! the configured camera (serial, user id, IP, MAC or device id), applying the
//! [`GigeConfig`] (pixel format, region, exposure, gain, frame rate, GigE stream settings),
//! and the stream with its preallocated buffers. Aravis objects are not `Send`: everything
//! here runs on the thread that then uses the camera.

use super::config::{AutoOr, GigeConfig};
use super::GigeError;
use aravis::prelude::*;
use aravis::{Auto, Buffer, Camera, GvStream, GvStreamPacketResend, GvStreamSocketBuffer, Stream};
use glib::translate::{from_glib_full, ToGlibPtr};
use std::ffi::{c_void, CStr, CString};
use std::sync::Mutex;

use aravis::glib;
use glib::prelude::Cast;

/// Aravis's device list and interface table are process-global and unguarded: omnirow calls
/// into them from one thread at a time.
static ARAVIS_GLOBAL: Mutex<()> = Mutex::new(());

/// One camera as Aravis's discovery sees it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct CameraInfo {
    /// Aravis device id (what `Camera::new` accepts).
    pub device_id: String,
    pub vendor: String,
    pub model: String,
    pub serial: String,
    /// IP address for GigE Vision cameras.
    pub address: String,
    /// MAC address for GigE Vision cameras.
    pub physical_id: String,
    /// GigEVision, USB3Vision or Fake.
    pub protocol: String,
}

fn cstr(p: *const std::ffi::c_char) -> String {
    if p.is_null() {
        String::new()
    } else {
        // SAFETY: Aravis returns NUL-terminated strings owned by its device list, valid until
        // the next list update, which ARAVIS_GLOBAL excludes while we copy them.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }
}

/// Updates Aravis's device list and returns every camera found on every enabled interface.
pub fn list_cameras() -> Vec<CameraInfo> {
    let _g = ARAVIS_GLOBAL.lock().unwrap_or_else(|e| e.into_inner());
    // SAFETY: plain calls into Aravis's global device list, serialised by ARAVIS_GLOBAL;
    // indices stay below arv_get_n_devices() of the update just made.
    unsafe {
        aravis_sys::arv_update_device_list();
        let n = aravis_sys::arv_get_n_devices();
        (0..n)
            .map(|i| CameraInfo {
                device_id: cstr(aravis_sys::arv_get_device_id(i)),
                vendor: cstr(aravis_sys::arv_get_device_vendor(i)),
                model: cstr(aravis_sys::arv_get_device_model(i)),
                serial: cstr(aravis_sys::arv_get_device_serial_nbr(i)),
                address: cstr(aravis_sys::arv_get_device_address(i)),
                physical_id: cstr(aravis_sys::arv_get_device_physical_id(i)),
                protocol: cstr(aravis_sys::arv_get_device_protocol(i)),
            })
            .collect()
    }
}

/// Enables one of Aravis's optional interfaces, e.g. `"Fake"`, the in-process fake camera
/// (device id `Fake_1`) used by tests and demos.
pub fn enable_interface(name: &str) {
    let Ok(c) = CString::new(name) else { return };
    let _g = ARAVIS_GLOBAL.lock().unwrap_or_else(|e| e.into_inner());
    // SAFETY: `c` is a valid C string for the duration of the call.
    unsafe { aravis_sys::arv_enable_interface(c.as_ptr()) };
}

fn normalise_mac(s: &str) -> Option<String> {
    let hex: String = s
        .chars()
        .filter(|c| !matches!(c, ':' | '-' | '.'))
        .collect::<String>()
        .to_ascii_lowercase();
    (hex.len() == 12 && hex.chars().all(|c| c.is_ascii_hexdigit())).then_some(hex)
}

/// Whether `wanted` names this camera (device id, serial, IP address, or MAC in any usual
/// notation).
pub fn matches(info: &CameraInfo, wanted: &str) -> bool {
    let w = wanted.trim();
    if w == info.device_id || w == info.serial || w == info.address {
        return true;
    }
    match (normalise_mac(w), normalise_mac(&info.physical_id)) {
        (Some(a), Some(b)) => a == b,
        _ => false,
    }
}

fn aravis_err(what: impl Into<String>) -> impl FnOnce(glib::Error) -> GigeError {
    let what = what.into();
    move |source| GigeError::Aravis {
        what,
        message: source.to_string(),
    }
}

/// Opens the configured camera: matched against the discovered list, or handed to Aravis as
/// is (Aravis also accepts a user id, and an IP address that discovery did not reach, e.g.
/// across a router or on loopback).
pub fn open_camera(wanted: Option<&str>) -> Result<Camera, GigeError> {
    let found = list_cameras();
    let _g = ARAVIS_GLOBAL.lock().unwrap_or_else(|e| e.into_inner());
    let name = match wanted {
        None => match found.first() {
            Some(c) => c.device_id.clone(),
            None => {
                return Err(GigeError::NotFound {
                    wanted: None,
                    found: vec![],
                })
            }
        },
        Some(w) => match found.iter().find(|c| matches(c, w)) {
            Some(c) => c.device_id.clone(),
            None => w.to_string(),
        },
    };
    Camera::new(Some(&name)).map_err(|e| {
        tracing::debug!(camera = %name, error = %e, "open failed");
        GigeError::NotFound {
            wanted: wanted.map(str::to_string),
            found: found
                .iter()
                .map(|c| {
                    format!(
                        "{} (serial {}, {}, {})",
                        c.device_id, c.serial, c.address, c.physical_id
                    )
                })
                .collect(),
        }
    })
}

/// What the camera was actually set to (read back after configuring).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SessionInfo {
    pub vendor: String,
    pub model: String,
    pub serial: String,
    pub width: u32,
    pub height: u32,
    pub pixel_format: String,
    /// The camera's frame rate, Hz (None when it has no frame-rate feature).
    pub frame_rate: Option<f64>,
    pub exposure_us: Option<f64>,
    pub payload_bytes: u32,
    /// GVSP packet size, bytes (GigE Vision only).
    pub packet_size: Option<u32>,
}

/// Applies the configuration to an open camera and reads back what it took.
pub fn configure(camera: &Camera, cfg: &GigeConfig) -> Result<SessionInfo, GigeError> {
    let want = cfg.pixel_format.genicam_name();
    let offered: Vec<String> = camera
        .dup_available_pixel_formats_as_strings()
        .map_err(aravis_err("reading PixelFormat entries"))?
        .into_iter()
        .map(|s| s.to_string())
        .collect();
    if !offered.iter().any(|f| f == want) {
        return Err(GigeError::PixelFormatUnavailable {
            wanted: want.to_string(),
            offered,
        });
    }
    camera
        .set_pixel_format_from_string(want)
        .map_err(aravis_err(format!("setting PixelFormat={want}")))?;

    let (w, h) = match cfg.roi {
        Some(r) => {
            camera
                .set_region(r.x as i32, r.y as i32, r.width as i32, r.height as i32)
                .map_err(aravis_err(format!(
                    "setting region {}x{}+{}+{}",
                    r.width, r.height, r.x, r.y
                )))?;
            (r.width, r.height)
        }
        None => {
            let (_, wmax) = camera
                .width_bounds()
                .map_err(aravis_err("reading Width bounds"))?;
            let (_, hmax) = camera
                .height_bounds()
                .map_err(aravis_err("reading Height bounds"))?;
            camera
                .set_region(0, 0, wmax, hmax)
                .map_err(aravis_err("setting the full-sensor region"))?;
            (wmax as u32, hmax as u32)
        }
    };
    let (_, _, rw, rh) = camera.region().map_err(aravis_err("reading the region"))?;
    if (rw as u32, rh as u32) != (w, h) {
        return Err(GigeError::Rejected {
            what: "region".into(),
            wanted: format!("{w}x{h}"),
            got: format!("{rw}x{rh}"),
        });
    }

    if let Some(e) = cfg.exposure_us {
        match e {
            AutoOr::Auto(_) => camera
                .set_exposure_time_auto(Auto::Continuous)
                .map_err(aravis_err("setting ExposureAuto=Continuous"))?,
            AutoOr::Fixed(us) => {
                if camera.is_exposure_auto_available().unwrap_or(false) {
                    camera
                        .set_exposure_time_auto(Auto::Off)
                        .map_err(aravis_err("setting ExposureAuto=Off"))?;
                }
                camera
                    .set_exposure_time(us)
                    .map_err(aravis_err(format!("setting exposure {us} µs")))?;
            }
        }
    }
    if let Some(g) = cfg.gain_db {
        match g {
            AutoOr::Auto(_) => camera
                .set_gain_auto(Auto::Continuous)
                .map_err(aravis_err("setting GainAuto=Continuous"))?,
            AutoOr::Fixed(db) => {
                if camera.is_gain_auto_available().unwrap_or(false) {
                    camera
                        .set_gain_auto(Auto::Off)
                        .map_err(aravis_err("setting GainAuto=Off"))?;
                }
                camera
                    .set_gain(db)
                    .map_err(aravis_err(format!("setting gain {db} dB")))?;
            }
        }
    }
    if let Some(f) = cfg.frame_rate {
        camera
            .set_frame_rate(f)
            .map_err(aravis_err(format!("setting frame rate {f} Hz")))?;
    }

    let mut packet_size = None;
    if camera.is_gv_device() {
        match cfg.stream.packet_size {
            AutoOr::Auto(_) => {
                camera
                    .gv_auto_packet_size()
                    .map_err(aravis_err("negotiating the GVSP packet size"))?;
            }
            AutoOr::Fixed(p) => {
                camera.gv_set_packet_size_adjustment(aravis::GvPacketSizeAdjustment::Never);
                camera
                    .gv_set_packet_size(p as i32)
                    .map_err(aravis_err(format!("setting GVSP packet size {p}")))?;
            }
        }
        packet_size = camera.gv_get_packet_size().ok();
        if let Some(bps) = cfg.stream.stream_bytes_per_second {
            if camera
                .is_feature_available("StreamBytesPerSecond")
                .unwrap_or(false)
            {
                camera
                    .set_integer("StreamBytesPerSecond", bps as i64)
                    .map_err(aravis_err(format!("setting StreamBytesPerSecond={bps}")))?;
            } else {
                tracing::warn!(
                    "stream_bytes_per_second: this camera has no StreamBytesPerSecond feature (Prosilica only); ignored"
                );
            }
        }
        camera.gv_set_stream_options(if cfg.stream.packet_socket {
            aravis::GvStreamOption::NONE
        } else {
            aravis::GvStreamOption::PACKET_SOCKET_DISABLED
        });
    }

    let s = |r: Result<glib::GString, glib::Error>| r.map(|g| g.to_string()).unwrap_or_default();
    let info = SessionInfo {
        vendor: s(camera.vendor_name()),
        model: s(camera.model_name()),
        serial: s(camera.device_serial_number()),
        width: w,
        height: h,
        pixel_format: s(camera.pixel_format_as_string()),
        frame_rate: camera
            .is_frame_rate_available()
            .unwrap_or(false)
            .then(|| camera.frame_rate().ok())
            .flatten(),
        exposure_us: camera.exposure_time().ok(),
        payload_bytes: camera
            .payload()
            .map_err(aravis_err("reading PayloadSize"))?,
        packet_size,
    };
    Ok(info)
}

/// Stream-thread callback: on the thread's start, ask for SCHED_FIFO at the priority passed
/// as user data.
unsafe extern "C" fn stream_thread_callback(
    user_data: *mut c_void,
    kind: aravis_sys::ArvStreamCallbackType,
    _buffer: *mut aravis_sys::ArvBuffer,
) {
    if kind == aravis_sys::ARV_STREAM_CALLBACK_TYPE_INIT {
        super::rt::make_current_thread_realtime("aravis-stream", user_data as usize as i32);
    }
}

/// Creates the stream (its receive thread real-time when asked), applies the GigE stream
/// settings, and queues `cfg.buffers` buffers of the camera's payload size.
pub fn create_stream(camera: &Camera, cfg: &GigeConfig, payload: u32) -> Result<Stream, GigeError> {
    let (callback, data): (aravis_sys::ArvStreamCallback, *mut c_void) = if cfg.realtime {
        (
            Some(stream_thread_callback),
            cfg.realtime_priority as usize as *mut c_void,
        )
    } else {
        (None, std::ptr::null_mut())
    };
    let stream: Stream = unsafe {
        // SAFETY: the camera pointer is valid for the call (borrowed from `camera`); the
        // callback is a plain function and its user data an integer, valid forever; a
        // non-null stream is returned with full ownership, else `error` is set.
        let mut error = std::ptr::null_mut();
        let raw = aravis_sys::arv_camera_create_stream(
            camera.to_glib_none().0,
            callback,
            data,
            &mut error,
        );
        if !error.is_null() {
            let e: glib::Error = from_glib_full(error);
            return Err(aravis_err("creating the stream")(e));
        }
        if raw.is_null() {
            return Err(GigeError::Aravis {
                what: "creating the stream".into(),
                message: "Aravis returned no stream".into(),
            });
        }
        from_glib_full(raw)
    };
    if let Some(gv) = stream.downcast_ref::<GvStream>() {
        gv.set_packet_resend(if cfg.stream.packet_resend {
            GvStreamPacketResend::Always
        } else {
            GvStreamPacketResend::Never
        });
        match cfg.stream.socket_buffer {
            AutoOr::Auto(_) => gv.set_socket_buffer(GvStreamSocketBuffer::Auto),
            AutoOr::Fixed(bytes) => {
                gv.set_socket_buffer(GvStreamSocketBuffer::Fixed);
                gv.set_socket_buffer_size(bytes as i32);
            }
        }
        if let Some(t) = cfg.stream.packet_timeout_ms {
            gv.set_packet_timeout(t * 1000);
        }
        if let Some(t) = cfg.stream.frame_retention_ms {
            gv.set_frame_retention(t * 1000);
        }
    }
    for _ in 0..cfg.buffers {
        stream.push_buffer(Buffer::new_allocate(payload as usize));
    }
    Ok(stream)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info() -> CameraInfo {
        CameraInfo {
            device_id: "Allied Vision Technologies-GC2450C (02-2141A)-06123".into(),
            vendor: "Allied Vision Technologies".into(),
            model: "GC2450C (02-2141A)".into(),
            serial: "02-2141A-06123".into(),
            address: "169.254.10.2".into(),
            physical_id: "00:0f:31:01:23:45".into(),
            protocol: "GigEVision".into(),
        }
    }

    #[test]
    fn matches_every_name() {
        let i = info();
        for w in [
            "02-2141A-06123",
            "169.254.10.2",
            "00:0F:31:01:23:45",
            "00-0f-31-01-23-45",
            "000f.3101.2345",
            " 02-2141A-06123 ",
            "Allied Vision Technologies-GC2450C (02-2141A)-06123",
        ] {
            assert!(matches(&i, w), "{w}");
        }
        for w in ["02-2141A-06124", "169.254.10.20", "00:0f:31:01:23:46", ""] {
            assert!(!matches(&i, w), "{w}");
        }
    }
}
