//! Publishing: where estimates go.
//!
//! Owns the [`Publisher`] seam the pipeline's publisher thread calls for every estimate (in
//! frame order) and with the [`StatusSummary`] once per status interval, and the publishers
//! omnirow ships: UDP JSON datagrams to unicast or multicast destinations ([`udp`]), JSON lines
//! on stdout ([`stdout`]), and the HTTP service ([`http`]: /healthz, /metrics from
//! [`metrics`], /status, /history.json and the live view from [`live`], /overlay.png from
//! [`overlay`]), which
//! reads the node's [`crate::status`] instead of being called. A ROS 2 publisher plugs in as
//! one more [`Publisher`]. Also the `[publish]` section of the
//! configuration (`[http]` is [`http`]'s).

pub mod http;
pub mod live;
pub mod metrics;
pub mod overlay;
pub mod stdout;
pub mod udp;

use crate::check::{Check, Raw};
use crate::estimate::Estimate;
use crate::frame::Frame;
use crate::status::StatusSummary;
use serde::Deserialize;
use std::net::Ipv4Addr;
use std::sync::Arc;
use stdout::StdoutMode;
use udp::UdpOptions;

/// Errors of a publisher (never fatal to the pipeline: it logs them and goes on).
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
}

/// A sink for estimates, called from the pipeline's publisher thread.
pub trait Publisher: Send {
    /// A short name for logs.
    fn name(&self) -> &str;
    /// Publishes one estimate; `frame` is the frame it was computed from (`None` for
    /// estimates without a frame, e.g. `camera_lost`). Must not block for long.
    fn publish(
        &mut self,
        estimate: &Estimate,
        frame: Option<&Arc<Frame>>,
    ) -> Result<(), PublishError>;
    /// The status summary, once per status interval.
    fn status(&mut self, _status: &StatusSummary) {}
    /// The pipeline is finishing: flush what is buffered.
    fn finish(&mut self) {}
}

/// `[publish]` of the node's configuration, as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPublish {
    udp: Raw<Vec<toml::Spanned<String>>>,
    multicast_ttl: Raw<i64>,
    multicast_loop: Raw<bool>,
    multicast_interface: Raw<String>,
    stdout: Raw<StdoutMode>,
    /// How often the status is logged and published: a pipeline option, checked there.
    pub(crate) status_interval_s: Raw<f64>,
}

impl RawPublish {
    /// Checks `[publish]` (but `status_interval_s`): the UDP destinations and options, and
    /// when estimates are printed on stdout.
    pub(crate) fn validate(&self, c: &mut Check) -> (UdpOptions, StdoutMode) {
        let mut destinations = Vec::new();
        if let Some(list) = &self.udp {
            for a in list.get_ref() {
                if let Some(a) = c.addr("publish.udp", a) {
                    destinations.push(a);
                }
            }
        }
        let multicast_interface = match &self.multicast_interface {
            None => Ipv4Addr::UNSPECIFIED,
            Some(s) => s.get_ref().parse().unwrap_or_else(|_| {
                c.bad(
                    "publish.multicast_interface",
                    s,
                    format!("`{}` is not an IPv4 address", s.get_ref()),
                );
                Ipv4Addr::UNSPECIFIED
            }),
        };
        let udp = UdpOptions {
            destinations,
            multicast_ttl: c.range("publish.multicast_ttl", &self.multicast_ttl, 1, 0, 255) as u32,
            multicast_loop: c.get(&self.multicast_loop, true),
            multicast_interface,
        };
        (udp, c.get(&self.stdout, StdoutMode::Auto))
    }
}
