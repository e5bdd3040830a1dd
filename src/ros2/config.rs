//! The `[ros2]` section of the node's configuration.
//!
//! Owns [`Ros2Config`] and its validation. It parses whether or not the crate was built with
//! the `ros2` feature, so a config file is checked the same way everywhere; only publishing
//! needs the feature.

use serde::{Deserialize, Serialize};
use std::net::IpAddr;

/// Highest DDS domain id whose RTPS ports fit in 16 bits with the standard port mapping
/// (7400 + 250 · domain + offsets); ROS 2 documents 0..=232 for Linux.
pub const MAX_DOMAIN_ID: u16 = 232;

/// Most poses on `row_path` (`path_length_m / path_step_m`).
pub const MAX_PATH_POSES: usize = 1000;

/// How a ROS 2 node named after omnirow joins the ROS 2 graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    /// Publish on ROS 2 at all.
    pub enabled: bool,
    /// DDS domain id (ROS_DOMAIN_ID). `None`: the `ROS_DOMAIN_ID` environment variable, or 0.
    pub domain_id: Option<u16>,
    /// Node namespace; the estimate topics live in it (`<namespace>/orientation`, ...).
    pub namespace: String,
    /// Node name, as `ros2 node list` shows it.
    pub node_name: String,
    /// `header.frame_id` of the estimate messages: the robot frame the orientation describes
    /// (REP 105 `base_link` unless the robot's TF tree says otherwise).
    pub frame_id: String,
    /// `header.frame_id` of `image_raw`: the camera's optical frame (the recorder's default).
    pub image_frame_id: String,
    /// `header.frame_id` of `row_pose`: the rows frame (x along the followed line in the
    /// direction of travel, y left, origin on the line abeam of the robot).
    pub rows_frame_id: String,
    /// Length of the followed line published on `row_path`, metres ahead of the robot.
    pub path_length_m: f64,
    /// Distance between the poses of `row_path`, metres.
    pub path_step_m: f64,
    /// Local IP addresses whose interfaces DDS may use (multicast and advertised unicast
    /// locators). Empty: all interfaces.
    pub networks: Vec<IpAddr>,
    /// QoS of the per-frame topics (`orientation`, `heading_tilt`, the `row_*` topics) and of
    /// `image_raw`.
    pub qos: QosConfig,
    /// QoS of the row guidance topics (`row_pose`, `row_path`, `row_offset`,
    /// `row_heading_error`): reliable by default, so that subscribers with ROS 2's default
    /// QoS (reliable: row-follow controllers, Nav2) match as well as best-effort ones.
    pub row_qos: QosConfig,
    /// Standard deviation of heading and tilt, degrees, at quality 1; it grows as 1/quality.
    pub sigma_deg_at_full_quality: f64,
    /// Frames on `<namespace>/image_raw` per second of capture time; 0 publishes no frames.
    pub image_rate_hz: f64,
    /// `nav_msgs/Odometry` topic to subscribe to for row guidance's motion model (forward
    /// speed and yaw rate of `twist`); a relative name lives in `namespace`. Empty: none (the
    /// configured `[guidance] speed_mps` is used).
    pub odometry_topic: String,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Ros2Config {
            enabled: false,
            domain_id: None,
            namespace: "/omnirow".to_string(),
            node_name: "omnirow".to_string(),
            frame_id: "base_link".to_string(),
            image_frame_id: "omnirow_camera".to_string(),
            rows_frame_id: "rows".to_string(),
            path_length_m: 5.0,
            path_step_m: 0.5,
            networks: Vec::new(),
            qos: QosConfig::default(),
            row_qos: QosConfig {
                reliability: Reliability::Reliable,
                depth: 5,
            },
            sigma_deg_at_full_quality: 1.0,
            image_rate_hz: 0.0,
            odometry_topic: String::new(),
        }
    }
}

/// Reliability of a topic, as ROS 2 names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Samples may be lost; never blocks the publisher (the sensor-data profile).
    BestEffort,
    /// Lost samples are resent; needed by subscribers that ask for reliable delivery.
    Reliable,
}

/// QoS of the per-frame topics: ROS 2's sensor-data profile by default (best effort,
/// volatile, keep last 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct QosConfig {
    pub reliability: Reliability,
    /// History depth (keep last N).
    pub depth: u32,
}

impl Default for QosConfig {
    fn default() -> Self {
        QosConfig {
            reliability: Reliability::BestEffort,
            depth: 5,
        }
    }
}

/// A `[ros2]` value that cannot work, naming the key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("ros2.{key}: {problem}")]
pub struct Ros2ConfigError {
    pub key: &'static str,
    pub problem: String,
}

impl Ros2Config {
    /// Checks every value; the error names the offending key.
    pub fn validate(&self) -> Result<(), Ros2ConfigError> {
        let err = |key: &'static str, problem: String| Err(Ros2ConfigError { key, problem });
        if let Some(d) = self.domain_id {
            if d > MAX_DOMAIN_ID {
                return err("domain_id", format!("{d} is above {MAX_DOMAIN_ID}"));
            }
        }
        if let Err(p) = check_namespace(&self.namespace) {
            return err("namespace", p);
        }
        if let Err(p) = check_token(&self.node_name) {
            return err("node_name", p);
        }
        if self.frame_id.is_empty() {
            return err("frame_id", "must not be empty".to_string());
        }
        if self.image_frame_id.is_empty() {
            return err("image_frame_id", "must not be empty".to_string());
        }
        if self.rows_frame_id.is_empty() {
            return err("rows_frame_id", "must not be empty".to_string());
        }
        if self.rows_frame_id == self.frame_id {
            return err(
                "rows_frame_id",
                format!(
                    "{:?} is also frame_id: the rows frame moves against the robot's",
                    self.rows_frame_id
                ),
            );
        }
        let (len, step) = (self.path_length_m, self.path_step_m);
        if !(step.is_finite() && step > 0.0) {
            return err("path_step_m", format!("{step} is not a distance > 0"));
        }
        if !(len.is_finite() && len >= step && len / step <= MAX_PATH_POSES as f64) {
            return err(
                "path_length_m",
                format!(
                    "{len} must be at least path_step_m ({step}) and at most {MAX_PATH_POSES} steps"
                ),
            );
        }
        if self.qos.depth == 0 {
            return err("qos.depth", "must be at least 1".to_string());
        }
        if self.row_qos.depth == 0 {
            return err("row_qos.depth", "must be at least 1".to_string());
        }
        let s = self.sigma_deg_at_full_quality;
        if !(s.is_finite() && s > 0.0 && s <= 180.0) {
            return err(
                "sigma_deg_at_full_quality",
                format!("{s} is not in (0, 180]"),
            );
        }
        let r = self.image_rate_hz;
        if !(r.is_finite() && r >= 0.0) {
            return err("image_rate_hz", format!("{r} is not a rate >= 0"));
        }
        let t = &self.odometry_topic;
        if !t.is_empty() {
            let rel = t.strip_prefix('/').unwrap_or(t);
            for tok in rel.split('/') {
                if let Err(p) = check_token(tok) {
                    return err("odometry_topic", format!("{t:?}: {p}"));
                }
            }
        }
        Ok(())
    }

    /// The odometry topic as (namespace, name), `None` when there is none: `/odom` is
    /// (`/`, `odom`), `odom` is (`namespace`, `odom`), `/robot/odom` (`/robot`, `odom`).
    pub fn odometry_topic_name(&self) -> Option<(String, String)> {
        let t = self.odometry_topic.as_str();
        if t.is_empty() {
            return None;
        }
        Some(match t.strip_prefix('/') {
            Some(abs) => match abs.rsplit_once('/') {
                Some((ns, base)) => (format!("/{ns}"), base.to_string()),
                None => ("/".to_string(), abs.to_string()),
            },
            None => match t.rsplit_once('/') {
                Some((ns, base)) => (join_ns(&self.namespace, ns), base.to_string()),
                None => (self.namespace.clone(), t.to_string()),
            },
        })
    }

    /// The domain id to join: the configured one, else `ROS_DOMAIN_ID`, else 0.
    pub fn resolved_domain_id(&self) -> Result<u16, Ros2ConfigError> {
        if let Some(d) = self.domain_id {
            return Ok(d);
        }
        match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => match v.trim().parse::<u16>() {
                Ok(d) if d <= MAX_DOMAIN_ID => Ok(d),
                _ => Err(Ros2ConfigError {
                    key: "domain_id",
                    problem: format!(
                        "unset, and ROS_DOMAIN_ID={v:?} is not a domain id in 0..={MAX_DOMAIN_ID}"
                    ),
                }),
            },
            _ => Ok(0),
        }
    }
}

/// A ROS 2 name token: ASCII letters, digits and `_`, not starting with a digit, no `__`.
fn check_token(t: &str) -> Result<(), String> {
    if t.is_empty() {
        return Err("must not be empty".to_string());
    }
    if let Some(c) = t
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
    {
        return Err(format!(
            "{t:?} contains {c:?} (only A-Z, a-z, 0-9 and _ allowed)"
        ));
    }
    if t.starts_with(|c: char| c.is_ascii_digit()) {
        return Err(format!("{t:?} starts with a digit"));
    }
    if t.contains("__") {
        return Err(format!("{t:?} contains a double underscore"));
    }
    Ok(())
}

/// The namespace `rel` (relative, no leading '/') inside `ns`.
fn join_ns(ns: &str, rel: &str) -> String {
    if ns == "/" {
        format!("/{rel}")
    } else {
        format!("{ns}/{rel}")
    }
}

/// An absolute ROS 2 namespace: `/` or `/tok(/tok)*`.
fn check_namespace(ns: &str) -> Result<(), String> {
    let Some(rest) = ns.strip_prefix('/') else {
        return Err(format!("{ns:?} must start with '/'"));
    };
    if rest.is_empty() {
        return Ok(());
    }
    for tok in rest.split('/') {
        if tok.is_empty() {
            return Err(format!(
                "{ns:?} has an empty component (trailing or double '/')"
            ));
        }
        check_token(tok).map_err(|p| format!("namespace {ns:?}: {p}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odometry_topic_names_resolve_and_bad_ones_are_named() {
        let mut c = Ros2Config::default();
        assert_eq!(c.odometry_topic_name(), None);
        let name = |c: &mut Ros2Config, t: &str| {
            c.odometry_topic = t.into();
            c.odometry_topic_name().unwrap()
        };
        assert_eq!(name(&mut c, "/odom"), ("/".into(), "odom".into()));
        assert_eq!(
            name(&mut c, "/robot/odom"),
            ("/robot".into(), "odom".into())
        );
        assert_eq!(name(&mut c, "odom"), ("/omnirow".into(), "odom".into()));
        assert_eq!(
            name(&mut c, "wheel/odom"),
            ("/omnirow/wheel".into(), "odom".into())
        );
        c.validate().unwrap();
        for bad in ["/odom/", "//odom", "/1odom", "od om"] {
            c.odometry_topic = bad.into();
            let e = c.validate().unwrap_err();
            assert_eq!(e.key, "odometry_topic", "{bad}: {e}");
        }
    }

    #[test]
    fn defaults_are_valid_and_match_the_documented_names() {
        let c = Ros2Config::default();
        c.validate().unwrap();
        assert_eq!(c.namespace, "/omnirow");
        assert_eq!(c.node_name, "omnirow");
        assert_eq!(c.qos.reliability, Reliability::BestEffort);
        assert_eq!(c.row_qos.reliability, Reliability::Reliable);
        assert!(!c.enabled);
    }

    #[test]
    fn parses_a_full_section() {
        let c: Ros2Config = toml::from_str(
            r#"
            enabled = true
            domain_id = 7
            namespace = "/farm/robot1"
            node_name = "rows"
            frame_id = "camera_link"
            image_frame_id = "cam_optical"
            rows_frame_id = "crop_rows"
            path_length_m = 3.0
            path_step_m = 0.25
            networks = ["127.0.0.1", "::1"]
            sigma_deg_at_full_quality = 0.5
            image_rate_hz = 2.0
            [qos]
            reliability = "reliable"
            depth = 10
            [row_qos]
            reliability = "best_effort"
            depth = 3
            "#,
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(c.domain_id, Some(7));
        assert_eq!(c.networks.len(), 2);
        assert_eq!(c.qos.reliability, Reliability::Reliable);
        assert_eq!(c.qos.depth, 10);
        assert_eq!(
            c.row_qos,
            QosConfig {
                reliability: Reliability::BestEffort,
                depth: 3
            }
        );
        assert_eq!(c.rows_frame_id, "crop_rows");
        assert_eq!((c.path_length_m, c.path_step_m), (3.0, 0.25));
    }

    #[test]
    fn unknown_keys_and_bad_values_are_rejected_naming_the_key() {
        let e = toml::from_str::<Ros2Config>("enabeld = true").unwrap_err();
        assert!(e.to_string().contains("enabeld"), "{e}");
        let e = toml::from_str::<Ros2Config>("[qos]\nreliability = \"sometimes\"").unwrap_err();
        assert!(e.to_string().contains("sometimes"), "{e}");

        let bad = |f: fn(&mut Ros2Config), key: &str| {
            let mut c = Ros2Config::default();
            f(&mut c);
            let e = c.validate().unwrap_err();
            assert_eq!(e.key, key, "{e}");
        };
        bad(|c| c.domain_id = Some(233), "domain_id");
        bad(|c| c.namespace = "omnirow".into(), "namespace");
        bad(|c| c.namespace = "/omnirow/".into(), "namespace");
        bad(|c| c.namespace = "/a//b".into(), "namespace");
        bad(|c| c.namespace = "/a-b".into(), "namespace");
        bad(|c| c.node_name = "".into(), "node_name");
        bad(|c| c.node_name = "9lives".into(), "node_name");
        bad(|c| c.node_name = "a__b".into(), "node_name");
        bad(|c| c.frame_id = "".into(), "frame_id");
        bad(|c| c.image_frame_id = "".into(), "image_frame_id");
        bad(|c| c.rows_frame_id = "".into(), "rows_frame_id");
        bad(|c| c.rows_frame_id = "base_link".into(), "rows_frame_id");
        bad(|c| c.path_step_m = 0.0, "path_step_m");
        bad(|c| c.path_step_m = f64::INFINITY, "path_step_m");
        bad(|c| c.path_length_m = 0.1, "path_length_m");
        bad(|c| c.path_length_m = f64::NAN, "path_length_m");
        bad(|c| c.path_length_m = 1000.0, "path_length_m");
        bad(|c| c.qos.depth = 0, "qos.depth");
        bad(|c| c.row_qos.depth = 0, "row_qos.depth");
        bad(
            |c| c.sigma_deg_at_full_quality = 0.0,
            "sigma_deg_at_full_quality",
        );
        bad(
            |c| c.sigma_deg_at_full_quality = f64::NAN,
            "sigma_deg_at_full_quality",
        );
        bad(|c| c.image_rate_hz = -1.0, "image_rate_hz");
    }

    #[test]
    fn root_and_nested_namespaces_are_accepted() {
        for ns in ["/", "/omnirow", "/farm/robot_1"] {
            check_namespace(ns).unwrap();
        }
    }

    #[test]
    fn configured_domain_wins_over_the_environment() {
        let c = Ros2Config {
            domain_id: Some(42),
            ..Ros2Config::default()
        };
        assert_eq!(c.resolved_domain_id().unwrap(), 42);
    }
}
