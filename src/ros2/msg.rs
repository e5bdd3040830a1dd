//! ROS 2 message types omnirow publishes, laid out field for field as their `.msg`/IDL
//! definitions so that serde's CDR encoding (RustDDS) is byte-identical to what rclcpp sends.
//!
//! Owns the Rust mirrors of `builtin_interfaces/Time`, `std_msgs/{Header, Float32}`,
//! `geometry_msgs/{Quaternion, Vector3, Vector3Stamped, Point, Pose, PoseStamped,
//! PoseWithCovariance, PoseWithCovarianceStamped, Twist, TwistWithCovariance}`,
//! `nav_msgs/{Path, Odometry}` (Odometry is read, not published),
//! `sensor_msgs/{Imu, Image}` and `diagnostic_msgs/{KeyValue, DiagnosticStatus,
//! DiagnosticArray}`, and the [`RosType`] trait that names each one's ROS package and type.
//! Field order is the wire order: do not reorder.

use serde::{Deserialize, Serialize};

/// The ROS 2 name of a message type (`package/msg/Name`).
pub trait RosType {
    /// ROS package, e.g. `sensor_msgs`.
    const PACKAGE: &'static str;
    /// Type name, e.g. `Imu`.
    const NAME: &'static str;

    /// The type as ROS 2 tools print it: `sensor_msgs/msg/Imu`.
    fn ros_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }

    /// The DDS type name rmw implementations register: `sensor_msgs::msg::dds_::Imu_`.
    fn dds_name() -> String {
        format!("{}::msg::dds_::{}_", Self::PACKAGE, Self::NAME)
    }
}

/// `builtin_interfaces/Time`: seconds and nanoseconds since the UNIX epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

/// A time that `builtin_interfaces/Time` cannot hold (its seconds are an `int32`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("time {ns} ns since the UNIX epoch is past builtin_interfaces/Time's range (year 2038)")]
pub struct TimeRangeError {
    pub ns: u64,
}

impl Time {
    /// From nanoseconds since the UNIX epoch.
    pub fn from_nanos(ns: u64) -> Result<Time, TimeRangeError> {
        let sec = i32::try_from(ns / 1_000_000_000).map_err(|_| TimeRangeError { ns })?;
        Ok(Time {
            sec,
            nanosec: (ns % 1_000_000_000) as u32,
        })
    }

    /// Nanoseconds since the UNIX epoch (negative times clamp to 0).
    pub fn to_nanos(self) -> u64 {
        (self.sec.max(0) as u64) * 1_000_000_000 + self.nanosec as u64
    }
}

impl RosType for Time {
    const PACKAGE: &'static str = "builtin_interfaces";
    const NAME: &'static str = "Time";
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl RosType for Header {
    const PACKAGE: &'static str = "std_msgs";
    const NAME: &'static str = "Header";
}

/// `geometry_msgs/Quaternion` (x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl RosType for Quaternion {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Quaternion";
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl RosType for Vector3 {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Vector3";
}

/// `geometry_msgs/Vector3Stamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3Stamped {
    pub header: Header,
    pub vector: Vector3,
}

impl RosType for Vector3Stamped {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Vector3Stamped";
}

/// `std_msgs/Float32`: a bare number, no header (what row-follow controllers take).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Float32 {
    pub data: f32,
}

impl RosType for Float32 {
    const PACKAGE: &'static str = "std_msgs";
    const NAME: &'static str = "Float32";
}

/// `geometry_msgs/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl RosType for Point {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Point";
}

/// `geometry_msgs/Pose`: a position and an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

impl RosType for Pose {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Pose";
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

impl RosType for PoseStamped {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "PoseStamped";
}

/// `geometry_msgs/PoseWithCovariance`. The covariance is row-major 6×6 over
/// (x, y, z, rotation about x, rotation about y, rotation about z).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    #[serde(with = "fixed_array")]
    pub covariance: [f64; 36],
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        PoseWithCovariance {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

impl RosType for PoseWithCovariance {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "PoseWithCovariance";
}

/// `geometry_msgs/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

impl RosType for PoseWithCovarianceStamped {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "PoseWithCovarianceStamped";
}

/// `geometry_msgs/Twist`: linear and angular velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

impl RosType for Twist {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "Twist";
}

/// `geometry_msgs/TwistWithCovariance`: the covariance row-major 6×6 over (vx, vy, vz, wx,
/// wy, wz).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "fixed_array")]
    pub covariance: [f64; 36],
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        TwistWithCovariance {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

impl RosType for TwistWithCovariance {
    const PACKAGE: &'static str = "geometry_msgs";
    const NAME: &'static str = "TwistWithCovariance";
}

/// `nav_msgs/Odometry` (omnirow subscribes to it): the pose in `header.frame_id`, the twist
/// in `child_frame_id` (the robot's base_link).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

impl RosType for Odometry {
    const PACKAGE: &'static str = "nav_msgs";
    const NAME: &'static str = "Odometry";
}

/// `nav_msgs/Path`: poses in `header.frame_id`, in order along the path.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Path {
    pub header: Header,
    pub poses: Vec<PoseStamped>,
}

impl RosType for Path {
    const PACKAGE: &'static str = "nav_msgs";
    const NAME: &'static str = "Path";
}

/// `sensor_msgs/Imu`. Covariances are row-major 3×3 about x, y, z; element 0 = −1 means
/// "this quantity is not provided".
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

impl RosType for Imu {
    const PACKAGE: &'static str = "sensor_msgs";
    const NAME: &'static str = "Imu";
}

/// `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    /// `mono8`, `rgb8`, `bayer_rggb8`, ... (sensor_msgs/image_encodings.hpp).
    pub encoding: String,
    pub is_bigendian: u8,
    /// Row length in bytes.
    pub step: u32,
    /// `uint8[]`: serialized as a CDR octet sequence in one copy, not byte by byte.
    #[serde(with = "octets")]
    pub data: Vec<u8>,
}

impl RosType for Image {
    const PACKAGE: &'static str = "sensor_msgs";
    const NAME: &'static str = "Image";
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

impl RosType for KeyValue {
    const PACKAGE: &'static str = "diagnostic_msgs";
    const NAME: &'static str = "KeyValue";
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// One of the `LEVEL_*` constants.
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}

impl RosType for DiagnosticStatus {
    const PACKAGE: &'static str = "diagnostic_msgs";
    const NAME: &'static str = "DiagnosticStatus";
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

impl RosType for DiagnosticArray {
    const PACKAGE: &'static str = "diagnostic_msgs";
    const NAME: &'static str = "DiagnosticArray";
}

/// serde for `uint8[]` through `serialize_bytes`: CDR writes a `uint32` length and the
/// bytes, exactly the layout of a sequence of octets, in one copy.
mod octets {
    use serde::{Deserializer, Serializer};

    pub fn serialize<S: Serializer>(data: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(data)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Vec<u8>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a sequence of octets")
            }
            fn visit_bytes<E>(self, v: &[u8]) -> Result<Vec<u8>, E> {
                Ok(v.to_vec())
            }
            fn visit_byte_buf<E>(self, v: Vec<u8>) -> Result<Vec<u8>, E> {
                Ok(v)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut a: A,
            ) -> Result<Vec<u8>, A::Error> {
                let mut out = Vec::with_capacity(a.size_hint().unwrap_or(0));
                while let Some(b) = a.next_element::<u8>()? {
                    out.push(b);
                }
                Ok(out)
            }
        }
        d.deserialize_bytes(V)
    }
}

/// serde for fixed-size arrays longer than serde's built-in 32 (`float64[36]`): a tuple of N
/// elements, which CDR writes without a length, exactly as the IDL's array. Small enough not
/// to warrant a dependency.
mod fixed_array {
    use serde::de::{Deserialize, Deserializer, Error, SeqAccess, Visitor};
    use serde::ser::{Serialize, SerializeTuple, Serializer};
    use std::marker::PhantomData;

    pub fn serialize<S: Serializer, T: Serialize, const N: usize>(
        a: &[T; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(N)?;
        for v in a {
            t.serialize_element(v)?;
        }
        t.end()
    }

    pub fn deserialize<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
    where
        D: Deserializer<'de>,
        T: Deserialize<'de> + Copy + Default,
    {
        struct V<T, const N: usize>(PhantomData<T>);
        impl<'de, T: Deserialize<'de> + Copy + Default, const N: usize> Visitor<'de> for V<T, N> {
            type Value = [T; N];
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "an array of {N} elements")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<[T; N], A::Error> {
                let mut out = [T::default(); N];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = a
                        .next_element()?
                        .ok_or_else(|| A::Error::invalid_length(i, &self))?;
                }
                Ok(out)
            }
        }
        d.deserialize_tuple(N, V::<T, N>(PhantomData))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_follow_the_rmw_convention() {
        assert_eq!(Imu::ros_name(), "sensor_msgs/msg/Imu");
        assert_eq!(Imu::dds_name(), "sensor_msgs::msg::dds_::Imu_");
        assert_eq!(
            DiagnosticArray::dds_name(),
            "diagnostic_msgs::msg::dds_::DiagnosticArray_"
        );
        assert_eq!(
            Vector3Stamped::dds_name(),
            "geometry_msgs::msg::dds_::Vector3Stamped_"
        );
    }

    #[test]
    fn time_from_nanos_splits_and_rejects_2038() {
        let t = Time::from_nanos(1_700_000_000_123_456_789).unwrap();
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
        assert_eq!(t.to_nanos(), 1_700_000_000_123_456_789);
        assert_eq!(Time::from_nanos(0).unwrap(), Time::default());
        let past = (i32::MAX as u64 + 1) * 1_000_000_000;
        assert_eq!(Time::from_nanos(past), Err(TimeRangeError { ns: past }));
        assert!(Time::from_nanos(past - 1).is_ok());
    }

    /// CDR layout against bytes written out by hand from the IDL (little endian, alignment
    /// counted from the start of the payload, as RTPS does after the encapsulation header).
    #[cfg(feature = "ros2")]
    #[test]
    fn vector3_stamped_cdr_bytes_match_the_idl_layout() {
        let m = Vector3Stamped {
            header: Header {
                stamp: Time { sec: 5, nanosec: 7 },
                frame_id: "base_link".into(),
            },
            vector: Vector3 {
                x: 1.0,
                y: -2.0,
                z: 0.5,
            },
        };
        let bytes = cdr::to_bytes(&m);
        let mut want = Vec::new();
        want.extend(5i32.to_le_bytes());
        want.extend(7u32.to_le_bytes());
        want.extend(10u32.to_le_bytes()); // "base_link" + NUL
        want.extend(b"base_link\0");
        want.extend([0u8; 2]); // 22 -> 24: align the doubles to 8
        for v in [1.0f64, -2.0, 0.5] {
            want.extend(v.to_le_bytes());
        }
        assert_eq!(bytes, want);
        assert_eq!(cdr::from_bytes::<Vector3Stamped>(&bytes), m);
    }

    #[cfg(feature = "ros2")]
    #[test]
    fn image_data_is_an_octet_sequence_and_round_trips() {
        let m = Image {
            header: Header {
                stamp: Time { sec: 1, nanosec: 2 },
                frame_id: "c".into(),
            },
            height: 2,
            width: 3,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: 3,
            data: vec![1, 2, 3, 4, 5, 6],
        };
        let bytes = cdr::to_bytes(&m);
        // header 4+4+4+"c\0"(2) = 14, pad to 16; height, width; "mono8\0": 4+6 = 10 -> 34;
        // is_bigendian at 34; pad to 36; step; data length; data.
        assert_eq!(&bytes[36..40], &3u32.to_le_bytes());
        assert_eq!(&bytes[40..44], &6u32.to_le_bytes());
        assert_eq!(&bytes[44..], &[1, 2, 3, 4, 5, 6]);
        assert_eq!(cdr::from_bytes::<Image>(&bytes), m);
    }

    #[cfg(feature = "ros2")]
    #[test]
    fn imu_and_diagnostics_round_trip() {
        let imu = Imu {
            header: Header {
                stamp: Time { sec: 9, nanosec: 1 },
                frame_id: "base_link".into(),
            },
            orientation: Quaternion {
                x: 0.1,
                y: 0.2,
                z: 0.3,
                w: 0.9,
            },
            orientation_covariance: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
            angular_velocity_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..Imu::default()
        };
        let bytes = cdr::to_bytes(&imu);
        // Header 4+4+4+10 = 22, pad 2, then 4 + 9 + 3 + 9 + 3 + 9 doubles.
        assert_eq!(bytes.len(), 24 + 8 * (4 + 9 + 3 + 9 + 3 + 9));
        assert_eq!(cdr::from_bytes::<Imu>(&bytes), imu);

        let d = DiagnosticArray {
            header: Header::default(),
            status: vec![DiagnosticStatus {
                level: DiagnosticStatus::WARN,
                name: "omnirow: pipeline".into(),
                message: "no rows".into(),
                hardware_id: "gc2450c".into(),
                values: vec![KeyValue {
                    key: "frames_in".into(),
                    value: "12".into(),
                }],
            }],
        };
        assert_eq!(cdr::from_bytes::<DiagnosticArray>(&cdr::to_bytes(&d)), d);
    }

    /// PoseWithCovarianceStamped: the 36 covariance doubles follow the pose with no length
    /// (a fixed IDL array), and the message round-trips.
    #[cfg(feature = "ros2")]
    #[test]
    fn pose_with_covariance_cdr_layout_and_round_trip() {
        let mut cov = [0.0; 36];
        for (i, c) in cov.iter_mut().enumerate() {
            *c = i as f64 * 0.5 - 3.0;
        }
        let m = PoseWithCovarianceStamped {
            header: Header {
                stamp: Time { sec: 3, nanosec: 4 },
                frame_id: "rows".into(),
            },
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Point {
                        x: 0.0,
                        y: 0.12,
                        z: 0.0,
                    },
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: -0.05,
                        w: 0.99875,
                    },
                },
                covariance: cov,
            },
        };
        let bytes = cdr::to_bytes(&m);
        // header 4+4+4+"rows\0"(5) = 17, pad to 24; 3 + 4 + 36 doubles.
        assert_eq!(bytes.len(), 24 + 8 * (3 + 4 + 36));
        assert_eq!(&bytes[24 + 8..24 + 16], &0.12f64.to_le_bytes());
        assert_eq!(&bytes[24 + 8 * 7..24 + 8 * 8], &(-3.0f64).to_le_bytes());
        assert_eq!(&bytes[bytes.len() - 8..], &14.5f64.to_le_bytes());
        assert_eq!(cdr::from_bytes::<PoseWithCovarianceStamped>(&bytes), m);
    }

    #[cfg(feature = "ros2")]
    #[test]
    fn path_and_float32_layout_and_round_trip() {
        let h = Header {
            stamp: Time { sec: 1, nanosec: 0 },
            frame_id: "b".into(),
        };
        let pose = |x: f64| PoseStamped {
            header: h.clone(),
            pose: Pose {
                position: Point { x, y: 0.0, z: 0.0 },
                orientation: Quaternion {
                    w: 1.0,
                    ..Quaternion::default()
                },
            },
        };
        let p = Path {
            header: h.clone(),
            poses: vec![pose(0.0), pose(0.5), pose(1.0)],
        };
        let bytes = cdr::to_bytes(&p);
        // header 4+4+4+"b\0" = 14; the sequence length at 16 (aligned to 4).
        assert_eq!(&bytes[16..20], &3u32.to_le_bytes());
        assert_eq!(cdr::from_bytes::<Path>(&bytes), p);
        assert_eq!(Path::dds_name(), "nav_msgs::msg::dds_::Path_");

        let f = Float32 { data: -0.125 };
        assert_eq!(cdr::to_bytes(&f), (-0.125f32).to_le_bytes());
        assert_eq!(cdr::from_bytes::<Float32>(&cdr::to_bytes(&f)), f);
        assert_eq!(Float32::ros_name(), "std_msgs/msg/Float32");
    }

    /// CDR little-endian through RustDDS's own (de)serializer: the one that publishes.
    #[cfg(feature = "ros2")]
    mod cdr {
        use ros2_client::dds::rustdds::serialization::{
            deserialize_from_cdr_with_rep_id, to_writer_with_rep_id,
        };
        use ros2_client::dds::rustdds::RepresentationIdentifier;

        pub fn to_bytes<T: serde::Serialize>(v: &T) -> Vec<u8> {
            let mut out = Vec::new();
            to_writer_with_rep_id(&mut out, v, RepresentationIdentifier::CDR_LE).unwrap();
            out
        }

        pub fn from_bytes<T: serde::de::DeserializeOwned>(b: &[u8]) -> T {
            let (v, used) =
                deserialize_from_cdr_with_rep_id::<T>(b, RepresentationIdentifier::CDR_LE).unwrap();
            assert_eq!(used, b.len(), "trailing bytes");
            v
        }
    }
}
