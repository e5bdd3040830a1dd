//! UDP: every estimate as one JSON datagram to each configured destination, unicast or
//! multicast (IPv4 or IPv6).

use super::{PublishError, Publisher};
use crate::estimate::Estimate;
use crate::frame::Frame;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::Arc;

/// UDP settings.
#[derive(Debug, Clone, PartialEq)]
pub struct UdpOptions {
    pub destinations: Vec<SocketAddr>,
    /// TTL (hop limit) of multicast datagrams.
    pub multicast_ttl: u32,
    /// Whether multicast datagrams loop back to this host.
    pub multicast_loop: bool,
    /// The IPv4 interface address multicast leaves through (unspecified: the OS's choice).
    pub multicast_interface: Ipv4Addr,
}

/// Sends estimates as JSON datagrams.
pub struct UdpPublisher {
    v4: Option<UdpSocket>,
    v6: Option<UdpSocket>,
    dests: Vec<SocketAddr>,
    failing: Vec<bool>,
}

impl UdpPublisher {
    /// Binds the sending sockets (errors name the destination they were for).
    pub fn new(opts: &UdpOptions) -> Result<Self, PublishError> {
        let io = |what: String| move |source| PublishError::Io { what, source };
        let mut v4 = None;
        let mut v6 = None;
        for d in &opts.destinations {
            match d.ip() {
                IpAddr::V4(ip) if v4.is_none() => {
                    let s = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
                        .map_err(io(format!("UDP socket for {d}")))?;
                    if ip.is_multicast() || opts.destinations.iter().any(|x| x.ip().is_multicast())
                    {
                        s.set_multicast_ttl_v4(opts.multicast_ttl)
                            .map_err(io(format!("multicast TTL for {d}")))?;
                        s.set_multicast_loop_v4(opts.multicast_loop)
                            .map_err(io(format!("multicast loop for {d}")))?;
                        if !opts.multicast_interface.is_unspecified() {
                            set_multicast_if_v4(&s, opts.multicast_interface)
                                .map_err(io(format!("multicast interface for {d}")))?;
                        }
                    }
                    v4 = Some(s);
                }
                IpAddr::V6(_) if v6.is_none() => {
                    let s = UdpSocket::bind((Ipv6Addr::UNSPECIFIED, 0))
                        .map_err(io(format!("UDP socket for {d}")))?;
                    s.set_multicast_loop_v6(opts.multicast_loop)
                        .map_err(io(format!("multicast loop for {d}")))?;
                    v6 = Some(s);
                }
                _ => {}
            }
        }
        Ok(UdpPublisher {
            v4,
            v6,
            failing: vec![false; opts.destinations.len()],
            dests: opts.destinations.clone(),
        })
    }
}

/// IP_MULTICAST_IF for an IPv4 socket (std has no setter for it).
fn set_multicast_if_v4(s: &UdpSocket, ip: Ipv4Addr) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let addr = libc::in_addr {
        s_addr: u32::from_ne_bytes(ip.octets()),
    };
    // SAFETY: a valid socket fd and a pointer to an in_addr of the given size.
    let rc = unsafe {
        libc::setsockopt(
            s.as_raw_fd(),
            libc::IPPROTO_IP,
            libc::IP_MULTICAST_IF,
            &addr as *const libc::in_addr as *const libc::c_void,
            std::mem::size_of::<libc::in_addr>() as libc::socklen_t,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

impl Publisher for UdpPublisher {
    fn name(&self) -> &str {
        "udp"
    }

    fn publish(&mut self, e: &Estimate, _frame: Option<&Arc<Frame>>) -> Result<(), PublishError> {
        let json = e.to_json();
        let mut first_err = None;
        for (i, d) in self.dests.iter().enumerate() {
            let sock = match d {
                SocketAddr::V4(_) => self.v4.as_ref(),
                SocketAddr::V6(_) => self.v6.as_ref(),
            };
            let Some(sock) = sock else { continue };
            match sock.send_to(json.as_bytes(), d) {
                Ok(_) => {
                    if self.failing[i] {
                        tracing::info!(destination = %d, "UDP sends work again");
                        self.failing[i] = false;
                    }
                }
                Err(source) => {
                    // Log once per outage, not per frame.
                    if !self.failing[i] {
                        tracing::warn!(destination = %d, "UDP send failed: {source}");
                        self.failing[i] = true;
                    }
                    first_err.get_or_insert(PublishError::Io {
                        what: format!("UDP to {d}"),
                        source,
                    });
                }
            }
        }
        first_err.map_or(Ok(()), Err)
    }
}
