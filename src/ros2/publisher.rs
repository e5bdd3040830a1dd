//! The ROS 2 node: a DDS participant (RustDDS through `ros2-client`), one node, and its
//! publishers.
//!
//! Owns [`Ros2Publisher`]: built once from a [`Ros2Config`], then called from the node's
//! publisher thread for every estimate, once a second for the status, and for frames (sent
//! on `image_raw` only at the configured rate). Publishing never blocks: the estimate topics
//! are best effort by default, and a reliable writer whose send window is full drops the
//! sample (counted in [`PublishCounts::would_block`]) rather than stall the pipeline.
//!
//! Topics (namespace `/omnirow` by default; they live in the node's namespace, so
//! `ros2 topic echo /omnirow/orientation` finds them):
//!
//! | topic | type | QoS |
//! |---|---|---|
//! | `<ns>/orientation` | `sensor_msgs/msg/Imu` | `[ros2.qos]`, sensor data by default |
//! | `<ns>/heading_tilt` | `geometry_msgs/msg/Vector3Stamped` | `[ros2.qos]` |
//! | `<ns>/image_raw` | `sensor_msgs/msg/Image` | `[ros2.qos]`; only if `image_rate_hz` > 0 |
//! | `<ns>/row_pose` | `geometry_msgs/msg/PoseWithCovarianceStamped` | `[ros2.row_qos]`, reliable by default |
//! | `<ns>/row_path` | `nav_msgs/msg/Path` | `[ros2.row_qos]` |
//! | `<ns>/row_offset` | `std_msgs/msg/Float32` | `[ros2.row_qos]` |
//! | `<ns>/row_heading_error` | `std_msgs/msg/Float32` | `[ros2.row_qos]` |
//! | `/diagnostics` | `diagnostic_msgs/msg/DiagnosticArray` | reliable, keep last 10 |
//!
//! The `row_*` topics carry the row guidance's tracked estimate; a frame without one (guidance
//! lost or disabled) publishes nothing on them.
//!
//! With `odometry_topic` set, the node also subscribes to `nav_msgs/msg/Odometry` there
//! (reliable or best-effort writers alike: the reader is best effort, keep last 5) and hands
//! the latest twist to row guidance ([`Ros2Publisher::subscribe_odometry`]).

use super::config::{QosConfig, Reliability, Ros2Config};
use super::convert::{ImageThrottle, MessageBuilder};
use super::error::Ros2Error;
use super::input::{RosEstimate, RosGuidance, RosStatus};
use super::msg::{
    DiagnosticArray, Float32, Image, Imu, Odometry, Path, PoseWithCovarianceStamped, RosType,
    Vector3Stamped,
};
use crate::frame::ImageView;
use crate::guidance::OdometryFeed;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
    Subscription, WriteError,
};
use serde::Serialize;
use std::sync::Arc;

/// A topic this node publishes, as ROS 2 names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// ROS name, e.g. `/omnirow/orientation`.
    pub name: String,
    /// DDS topic name, e.g. `rt/omnirow/orientation`.
    pub dds_name: String,
    /// ROS type, e.g. `sensor_msgs/msg/Imu`.
    pub ros_type: String,
    /// DDS type, e.g. `sensor_msgs::msg::dds_::Imu_`.
    pub dds_type: String,
}

/// Messages sent and dropped since the publisher was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PublishCounts {
    pub orientation: u64,
    pub heading_tilt: u64,
    pub diagnostics: u64,
    pub images: u64,
    pub row_pose: u64,
    pub row_path: u64,
    /// `row_offset` and `row_heading_error` pairs.
    pub row_follow: u64,
    /// Samples a reliable writer refused because its send window was full.
    pub would_block: u64,
    /// `nav_msgs/Odometry` samples received (and handed to guidance when finite).
    pub odometry_in: u64,
}

/// The odometry subscription and where its samples go.
struct OdometryIn {
    subscription: Subscription<Odometry>,
    feed: Arc<OdometryFeed>,
    topic: String,
}

/// A typed writer and the topic it writes.
struct Writer<M: Serialize> {
    publisher: Publisher<M>,
    topic: TopicInfo,
}

/// The ROS 2 node omnirow runs; see the module doc for its topics.
pub struct Ros2Publisher {
    // Field order is drop order: writers first, then the node, then the participant.
    orientation: Writer<Imu>,
    heading_tilt: Writer<Vector3Stamped>,
    row_pose: Writer<PoseWithCovarianceStamped>,
    row_path: Writer<Path>,
    row_offset: Writer<Float32>,
    row_heading_error: Writer<Float32>,
    diagnostics: Writer<DiagnosticArray>,
    image: Option<Writer<Image>>,
    odometry: Option<OdometryIn>,
    builder: MessageBuilder,
    throttle: ImageThrottle,
    counts: PublishCounts,
    node: Node,
    context: Context,
}

impl std::fmt::Debug for Ros2Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Publisher")
            .field("node", &self.node.fully_qualified_name())
            .field("domain_id", &self.context.domain_id())
            .field("counts", &self.counts)
            .finish()
    }
}

fn create_err(what: impl Into<String>) -> impl FnOnce(String) -> Ros2Error {
    let what = what.into();
    move |reason| Ros2Error::Create { what, reason }
}

impl Ros2Publisher {
    /// Joins the DDS domain, creates the node and its publishers. The node announces itself
    /// on `ros_discovery_info` (as every rmw does), so `ros2 node list` shows it.
    pub fn new(config: &Ros2Config) -> Result<Ros2Publisher, Ros2Error> {
        config.validate()?;
        let domain = config.resolved_domain_id()?;
        let mut dpb = DomainParticipantBuilder::new(domain);
        if !config.networks.is_empty() {
            dpb = dpb.with_only_networks(config.networks.iter().copied());
        }
        let participant = dpb
            .build()
            .map_err(|e| e.to_string())
            .map_err(create_err(format!("DDS participant in domain {domain}")))?;
        let context = Context::from_domain_participant(participant)
            .map_err(|e| e.to_string())
            .map_err(create_err("ROS 2 context"))?;
        let node_name = NodeName::new(&config.namespace, &config.node_name)
            .map_err(|e| format!("{e:?}"))
            .map_err(create_err(format!(
                "node {:?} in namespace {:?}",
                config.node_name, config.namespace
            )))?;
        let mut node = context
            .new_node(
                node_name,
                NodeOptions::new()
                    .enable_rosout(false)
                    .start_parameter_services(false),
            )
            .map_err(|e| format!("{e:?}"))
            .map_err(create_err("ROS 2 node"))?;

        let frame_qos = qos_profile(&config.qos);
        let row_qos = qos_profile(&config.row_qos);
        // rclcpp's default QoS, which diagnostic_aggregator and `ros2 topic echo` request.
        let diagnostics_qos = QosProfile::publisher_default()
            .reliability_reliable(WhenFull::Fail)
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 10 });

        let ns = config.namespace.as_str();
        let orientation = writer::<Imu>(&mut node, ns, "orientation", &frame_qos)?;
        let heading_tilt = writer::<Vector3Stamped>(&mut node, ns, "heading_tilt", &frame_qos)?;
        let row_pose = writer::<PoseWithCovarianceStamped>(&mut node, ns, "row_pose", &row_qos)?;
        let row_path = writer::<Path>(&mut node, ns, "row_path", &row_qos)?;
        let row_offset = writer::<Float32>(&mut node, ns, "row_offset", &row_qos)?;
        let row_heading_error = writer::<Float32>(&mut node, ns, "row_heading_error", &row_qos)?;
        let diagnostics =
            writer::<DiagnosticArray>(&mut node, "/", "diagnostics", &diagnostics_qos)?;
        let image = if config.image_rate_hz > 0.0 {
            Some(writer::<Image>(&mut node, ns, "image_raw", &frame_qos)?)
        } else {
            None
        };
        tracing::info!(
            node = %node.fully_qualified_name(),
            domain,
            networks = ?config.networks,
            "ROS 2 node up"
        );
        Ok(Ros2Publisher {
            orientation,
            heading_tilt,
            row_pose,
            row_path,
            row_offset,
            row_heading_error,
            diagnostics,
            image,
            odometry: None,
            builder: MessageBuilder::new(config),
            throttle: ImageThrottle::new(config.image_rate_hz),
            counts: PublishCounts::default(),
            node,
            context,
        })
    }

    /// The node's fully qualified name, e.g. `/omnirow/omnirow`.
    pub fn node_name(&self) -> String {
        self.node.fully_qualified_name()
    }

    /// The DDS domain the node joined.
    pub fn domain_id(&self) -> u16 {
        self.context.domain_id()
    }

    /// The topics this node publishes.
    pub fn topics(&self) -> Vec<TopicInfo> {
        let mut t = vec![
            self.orientation.topic.clone(),
            self.heading_tilt.topic.clone(),
            self.row_pose.topic.clone(),
            self.row_path.topic.clone(),
            self.row_offset.topic.clone(),
            self.row_heading_error.topic.clone(),
            self.diagnostics.topic.clone(),
        ];
        if let Some(i) = &self.image {
            t.push(i.topic.clone());
        }
        t
    }

    /// Messages sent and dropped so far.
    pub fn counts(&self) -> PublishCounts {
        self.counts
    }

    /// The row guidance's tool point (base_link x, y, metres; see
    /// [`MessageBuilder::with_tool_point`]).
    pub fn set_tool_point(&mut self, tool_point_m: [f64; 2]) {
        self.builder = self.builder.clone().with_tool_point(tool_point_m);
    }

    /// Subscribes to `nav_msgs/Odometry` on `config.odometry_topic` (nothing when it is
    /// empty); each sample's forward speed (`twist.linear.x`) and yaw rate (`twist.angular.z`)
    /// go to `feed`, stamped with the wall clock when it is read ([`Self::poll_odometry`]):
    /// guidance judges staleness by arrival, not by the sender's clock.
    pub fn subscribe_odometry(
        &mut self,
        config: &Ros2Config,
        feed: Arc<OdometryFeed>,
    ) -> Result<(), Ros2Error> {
        let Some((ns, base)) = config.odometry_topic_name() else {
            return Ok(());
        };
        let full = config.odometry_topic.clone();
        let name = Name::new(&ns, &base)
            .map_err(|e| format!("{e:?}"))
            .map_err(create_err(format!("topic name {full}")))?;
        let qos = QosProfile::subscription_default()
            .reliability_best_effort()
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 5 });
        let topic = self
            .node
            .create_topic(
                &name,
                MessageTypeName::new(Odometry::PACKAGE, Odometry::NAME),
                &qos,
            )
            .map_err(|e| e.to_string())
            .map_err(create_err(format!("topic {full}")))?;
        let subscription = self
            .node
            .create_subscription::<Odometry>(&topic, None)
            .map_err(|e| e.to_string())
            .map_err(create_err(format!("subscription on {full}")))?;
        tracing::info!(topic = %full, "row guidance reads odometry");
        self.odometry = Some(OdometryIn {
            subscription,
            feed,
            topic: full,
        });
        Ok(())
    }

    /// Reads the odometry samples that arrived and hands the latest to guidance; the number
    /// read.
    pub fn poll_odometry(&mut self) -> usize {
        let Some(o) = &self.odometry else {
            return 0;
        };
        let mut latest = None;
        let mut n = 0;
        loop {
            match o.subscription.take() {
                Ok(Some((m, _))) => {
                    n += 1;
                    latest = Some(m);
                }
                Ok(None) => break,
                Err(e) => {
                    tracing::debug!(topic = %o.topic, "odometry: {e:?}");
                    break;
                }
            }
        }
        if let Some(m) = latest {
            let odom = crate::guidance::Odometry {
                stamp_ns: crate::frame::now_ns(),
                speed_mps: m.twist.twist.linear.x,
                yaw_rate_rps: m.twist.twist.angular.z,
            };
            if odom.speed_mps.is_finite() && odom.yaw_rate_rps.is_finite() {
                o.feed.put(odom);
            }
        }
        self.counts.odometry_in += n as u64;
        n
    }

    /// Publishes one frame's estimate: `orientation` and `heading_tilt` when it has heading
    /// and tilt, the `row_*` topics when its guidance has a tracked estimate. Returns whether
    /// the frame had heading and tilt. Reads the odometry that arrived first.
    pub fn publish_estimate(&mut self, e: &RosEstimate) -> Result<bool, Ros2Error> {
        self.poll_odometry();
        self.publish_rows(e)?;
        let (Some(imu), Some(ht)) = (self.builder.imu(e)?, self.builder.heading_tilt(e)?) else {
            return Ok(false);
        };
        if send(&self.orientation, imu, &mut self.counts.would_block)? {
            self.counts.orientation += 1;
        }
        if send(&self.heading_tilt, ht, &mut self.counts.would_block)? {
            self.counts.heading_tilt += 1;
        }
        Ok(true)
    }

    /// `row_pose`, `row_path`, `row_offset` and `row_heading_error` of a frame with a tracked
    /// guidance estimate; nothing otherwise.
    fn publish_rows(&mut self, e: &RosEstimate) -> Result<(), Ros2Error> {
        let block = &mut self.counts.would_block;
        if let Some(m) = self.builder.row_pose(e)? {
            if send(&self.row_pose, m, block)? {
                self.counts.row_pose += 1;
            }
        }
        if let Some(m) = self.builder.row_path(e)? {
            if send(&self.row_path, m, block)? {
                self.counts.row_path += 1;
            }
        }
        if let Some((offset, heading)) = MessageBuilder::row_follow(e) {
            let a = send(&self.row_offset, offset, block)?;
            if send(&self.row_heading_error, heading, block)? && a {
                self.counts.row_follow += 1;
            }
        }
        Ok(())
    }

    /// Publishes the status summary on `/diagnostics` with the latest frame's guidance (its
    /// own status, `<node>: guidance`), stamped with the wall clock. The node calls it once a
    /// second.
    pub fn publish_status(
        &mut self,
        s: &RosStatus,
        guidance: Option<&RosGuidance>,
    ) -> Result<(), Ros2Error> {
        let now_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or(0);
        self.publish_status_at(s, guidance, now_ns)
    }

    /// As [`Self::publish_status`], stamped `now_ns` (nanoseconds since the UNIX epoch).
    pub fn publish_status_at(
        &mut self,
        s: &RosStatus,
        guidance: Option<&RosGuidance>,
        now_ns: u64,
    ) -> Result<(), Ros2Error> {
        self.poll_odometry();
        let d = self.builder.diagnostics(s, guidance, now_ns)?;
        if send(&self.diagnostics, d, &mut self.counts.would_block)? {
            self.counts.diagnostics += 1;
        }
        Ok(())
    }

    /// Offers a frame for `image_raw`: sent (copied) when images are enabled and one is due
    /// at `image_rate_hz` of capture time. Returns whether it was sent.
    pub fn publish_frame(&mut self, view: &ImageView, capture_ns: u64) -> Result<bool, Ros2Error> {
        let Some(w) = &self.image else {
            return Ok(false);
        };
        if !self.throttle.due(capture_ns) {
            return Ok(false);
        }
        let msg = self.builder.image(view, capture_ns)?;
        let sent = send(w, msg, &mut self.counts.would_block)?;
        if sent {
            self.counts.images += 1;
        }
        Ok(sent)
    }
}

/// The QoS of per-frame topics from `[ros2.qos]` or `[ros2.row_qos]`.
fn qos_profile(qos: &QosConfig) -> QosProfile {
    let base = QosProfile::subscription_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast {
            depth: qos.depth as usize,
        });
    match qos.reliability {
        Reliability::BestEffort => base.reliability_best_effort(),
        Reliability::Reliable => base.reliability_reliable(WhenFull::Fail),
    }
}

fn writer<M: RosType + Serialize>(
    node: &mut Node,
    namespace: &str,
    base: &str,
    qos: &QosProfile,
) -> Result<Writer<M>, Ros2Error> {
    let full = if namespace == "/" {
        format!("/{base}")
    } else {
        format!("{namespace}/{base}")
    };
    let name = Name::new(namespace, base)
        .map_err(|e| format!("{e:?}"))
        .map_err(create_err(format!("topic name {full}")))?;
    let topic = node
        .create_topic(&name, MessageTypeName::new(M::PACKAGE, M::NAME), qos)
        .map_err(|e| e.to_string())
        .map_err(create_err(format!("topic {full}")))?;
    let publisher = node
        .create_publisher::<M>(&topic, None)
        .map_err(|e| e.to_string())
        .map_err(create_err(format!("publisher on {full}")))?;
    Ok(Writer {
        publisher,
        topic: TopicInfo {
            dds_name: format!("rt{full}"),
            name: full,
            ros_type: M::ros_name(),
            dds_type: M::dds_name(),
        },
    })
}

/// Writes one sample. A full reliable send window drops it (counted, logged at debug),
/// anything else is an error naming the topic.
fn send<M: Serialize>(w: &Writer<M>, msg: M, would_block: &mut u64) -> Result<bool, Ros2Error> {
    match w.publisher.publish(msg) {
        Ok(()) => Ok(true),
        Err(WriteError::WouldBlock { .. }) => {
            *would_block += 1;
            tracing::debug!(topic = %w.topic.name, "send window full: sample dropped");
            Ok(false)
        }
        Err(e) => Err(Ros2Error::Write {
            topic: w.topic.name.clone(),
            reason: e.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send<T: Send>() {}

    #[test]
    fn the_publisher_can_move_to_the_publisher_thread() {
        assert_send::<Ros2Publisher>();
    }

    #[test]
    fn qos_follows_the_config() {
        let mut c = Ros2Config::default();
        let q = qos_profile(&c.qos);
        assert_eq!(q.reliability, ros2_client::qos::Reliability::BestEffort);
        assert_eq!(q.history, History::KeepLast { depth: 5 });
        // The row topics: reliable by default, serving default-QoS subscribers.
        assert!(matches!(
            qos_profile(&c.row_qos).reliability,
            ros2_client::qos::Reliability::Reliable { .. }
        ));
        c.qos.reliability = Reliability::Reliable;
        c.qos.depth = 2;
        let q = qos_profile(&c.qos);
        assert!(matches!(
            q.reliability,
            ros2_client::qos::Reliability::Reliable { .. }
        ));
        assert_eq!(q.history, History::KeepLast { depth: 2 });
    }

    #[test]
    fn a_bad_config_fails_before_touching_the_network() {
        let c = Ros2Config {
            node_name: "bad name".into(),
            ..Ros2Config::default()
        };
        let e = Ros2Publisher::new(&c).unwrap_err();
        assert!(e.to_string().contains("ros2.node_name"), "{e}");
    }
}
