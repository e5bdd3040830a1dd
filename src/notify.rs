//! The systemd notify protocol (sd_notify(3)) over the Unix datagram socket named by
//! `$NOTIFY_SOCKET`, with std's `UnixDatagram` (no crate needed).
//!
//! Owns READY=1, WATCHDOG=1, STATUS=… and STOPPING=1 messages and the watchdog interval
//! (`$WATCHDOG_USEC`, honoured only when `$WATCHDOG_PID` is unset or ours). Without
//! `$NOTIFY_SOCKET` every call is a no-op, so the node runs the same outside systemd. The
//! caller decides *when* to send (the node: READY once the source delivers frames, WATCHDOG
//! only while the pipeline is alive).

use std::os::unix::net::UnixDatagram;
use std::time::Duration;

/// Errors opening the notify socket.
#[derive(Debug, thiserror::Error)]
pub enum NotifyError {
    #[error("NOTIFY_SOCKET={0:?}: {1}")]
    Socket(String, std::io::Error),
    #[error("NOTIFY_SOCKET={0:?}: unsupported address (a path or an @abstract name)")]
    Address(String),
}

/// A connection to the service manager (or nothing, outside systemd).
#[derive(Debug)]
pub struct Notifier {
    sock: Option<(UnixDatagram, String)>,
    watchdog: Option<Duration>,
}

impl Notifier {
    /// Reads `$NOTIFY_SOCKET`, `$WATCHDOG_USEC` and `$WATCHDOG_PID`.
    pub fn from_env() -> Result<Self, NotifyError> {
        let watchdog = std::env::var("WATCHDOG_USEC")
            .ok()
            .and_then(|v| v.parse::<u64>().ok())
            .filter(|&us| us > 0)
            .filter(|_| {
                std::env::var("WATCHDOG_PID")
                    .ok()
                    .and_then(|p| p.parse::<u32>().ok())
                    .is_none_or(|p| p == std::process::id())
            })
            .map(Duration::from_micros);
        let sock = match std::env::var("NOTIFY_SOCKET") {
            Ok(addr) if !addr.is_empty() => Some(Self::connect(&addr)?),
            _ => None,
        };
        Ok(Notifier { sock, watchdog })
    }

    /// A notifier that sends nothing.
    pub fn disabled() -> Self {
        Notifier {
            sock: None,
            watchdog: None,
        }
    }

    fn connect(addr: &str) -> Result<(UnixDatagram, String), NotifyError> {
        let err = |e| NotifyError::Socket(addr.to_string(), e);
        let sock = UnixDatagram::unbound().map_err(err)?;
        if let Some(name) = addr.strip_prefix('@') {
            use std::os::linux::net::SocketAddrExt;
            let a =
                std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes()).map_err(err)?;
            sock.connect_addr(&a).map_err(err)?;
        } else if addr.starts_with('/') {
            sock.connect(addr).map_err(err)?;
        } else {
            return Err(NotifyError::Address(addr.to_string()));
        }
        Ok((sock, addr.to_string()))
    }

    /// True when a service manager listens.
    pub fn enabled(&self) -> bool {
        self.sock.is_some()
    }

    /// How often WATCHDOG=1 should be sent (half the manager's timeout), if it asks for it.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        self.watchdog.map(|d| d / 2)
    }

    /// Sends one notification (lines of `KEY=VALUE`). Failures are logged, never fatal.
    pub fn notify(&self, msg: &str) {
        if let Some((s, addr)) = &self.sock {
            if let Err(e) = s.send(msg.as_bytes()) {
                tracing::warn!(socket = %addr, "systemd notify failed: {e}");
            }
        }
    }

    pub fn ready(&self, status: &str) {
        self.notify(&format!("READY=1\nSTATUS={}", one_line(status)));
    }

    pub fn watchdog(&self) {
        self.notify("WATCHDOG=1");
    }

    pub fn status(&self, status: &str) {
        self.notify(&format!("STATUS={}", one_line(status)));
    }

    pub fn stopping(&self, status: &str) {
        self.notify(&format!("STOPPING=1\nSTATUS={}", one_line(status)));
    }
}

fn one_line(s: &str) -> String {
    s.replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sends_to_a_path_socket_and_abstract_names() {
        let dir = std::env::temp_dir().join(format!("omnirow-notify-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let server = UnixDatagram::bind(&path).unwrap();
        let n = Notifier {
            sock: Some(Notifier::connect(path.to_str().unwrap()).unwrap()),
            watchdog: Some(Duration::from_secs(10)),
        };
        n.ready("streaming\n15 fps");
        let mut buf = [0u8; 256];
        let k = server.recv(&mut buf).unwrap();
        assert_eq!(
            std::str::from_utf8(&buf[..k]).unwrap(),
            "READY=1\nSTATUS=streaming 15 fps"
        );
        assert_eq!(n.watchdog_interval(), Some(Duration::from_secs(5)));

        let name = format!("omnirow-test-{}", std::process::id());
        use std::os::linux::net::SocketAddrExt;
        let a = std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes()).unwrap();
        let server = UnixDatagram::bind_addr(&a).unwrap();
        let n = Notifier {
            sock: Some(Notifier::connect(&format!("@{name}")).unwrap()),
            watchdog: None,
        };
        n.stopping("bye");
        let k = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..k], b"STOPPING=1\nSTATUS=bye");
        assert!(matches!(
            Notifier::connect("relative"),
            Err(NotifyError::Address(_))
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
