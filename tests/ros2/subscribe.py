#!/usr/bin/env python3
"""An independent ROS 2 subscriber: Eclipse Cyclone DDS (the `cyclonedds` wheel), no ROS.

Subscribes to the topics omnirow publishes, with IDL types written here from the ROS 2
message definitions (not from omnirow's code), and prints every decoded sample as one JSON
line on stdout. Also reads `ros_discovery_info` (rmw_dds_common/ParticipantEntitiesInfo),
which is how `ros2 node list` finds nodes. Exits 0 once it has the wanted number of samples
of each kind, 1 on timeout (saying what is missing on stderr), 2 on bad usage.

Cyclone is confined to loopback by cyclonedds-loopback.xml beside this file (NetworkInterface
lo, no multicast, peer 127.0.0.1) unless CYCLONEDDS_URI is already set.

    subscribe.py --domain 17 --namespace /omnirow --want orientation=5 --want discovery=1
"""

import argparse
import json
import os
import struct
import sys
import time
from dataclasses import dataclass

# Must be set before cyclonedds loads its configuration.
os.environ.setdefault(
    "CYCLONEDDS_URI",
    "file://" + os.path.join(os.path.dirname(os.path.abspath(__file__)), "cyclonedds-loopback.xml"),
)

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl import types as t  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


# --- ROS 2 message definitions as DDS IDL (rosidl's mapping: pkg::msg::dds_::Name_) ---

@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str


@dataclass
class Quaternion_(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64
    y: t.float64
    z: t.float64
    w: t.float64


@dataclass
class Vector3_(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Vector3Stamped_(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3Stamped_"):
    header: Header_
    vector: Vector3_


@dataclass
class Imu_(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header_
    orientation: Quaternion_
    orientation_covariance: t.array[t.float64, 9]
    angular_velocity: Vector3_
    angular_velocity_covariance: t.array[t.float64, 9]
    linear_acceleration: Vector3_
    linear_acceleration_covariance: t.array[t.float64, 9]


@dataclass
class Image_(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header_
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
class Float32_(IdlStruct, typename="std_msgs::msg::dds_::Float32_"):
    data: t.float32


@dataclass
class Point_(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64
    y: t.float64
    z: t.float64


@dataclass
class Pose_(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point_
    orientation: Quaternion_


@dataclass
class PoseStamped_(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header_
    pose: Pose_


@dataclass
class PoseWithCovariance_(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose_
    covariance: t.array[t.float64, 36]


@dataclass
class PoseWithCovarianceStamped_(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header_
    pose: PoseWithCovariance_


@dataclass
class Path_(IdlStruct, typename="nav_msgs::msg::dds_::Path_"):
    header: Header_
    poses: t.sequence[PoseStamped_]


@dataclass
class KeyValue_(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus_(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: t.uint8
    name: str
    message: str
    hardware_id: str
    values: t.sequence[KeyValue_]


@dataclass
class DiagnosticArray_(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header_
    status: t.sequence[DiagnosticStatus_]


# rmw_dds_common (Iron and later: 16-byte gids).
@dataclass
class Gid_(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: t.array[t.uint8, 16]


@dataclass
class NodeEntitiesInfo_(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: str
    node_name: str
    reader_gid_seq: t.sequence[Gid_]
    writer_gid_seq: t.sequence[Gid_]


@dataclass
class ParticipantEntitiesInfo_(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    gid: Gid_
    node_entities_info_seq: t.sequence[NodeEntitiesInfo_]


def header(h):
    return {"stamp": [h.stamp.sec, h.stamp.nanosec], "frame_id": h.frame_id}


def pose(p):
    return {
        "position": [p.position.x, p.position.y, p.position.z],
        "orientation": [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w],
    }


def decode(kind, m):
    if kind == "row_pose":
        return {
            "header": header(m.header),
            "pose": pose(m.pose.pose),
            "covariance": list(m.pose.covariance),
        }
    if kind == "row_path":
        return {
            "header": header(m.header),
            "poses": [{"header": header(p.header), "pose": pose(p.pose)} for p in m.poses],
        }
    if kind in ("row_offset", "row_heading_error"):
        # The float32's bit pattern too, for an exact comparison.
        return {"data": m.data, "bits": struct.unpack("<I", struct.pack("<f", m.data))[0]}
    if kind == "orientation":
        q = m.orientation
        return {
            "header": header(m.header),
            "orientation": [q.x, q.y, q.z, q.w],
            "orientation_covariance": list(m.orientation_covariance),
            "angular_velocity_covariance": list(m.angular_velocity_covariance),
            "linear_acceleration_covariance": list(m.linear_acceleration_covariance),
        }
    if kind == "heading_tilt":
        v = m.vector
        return {
            "header": header(m.header),
            "vector": [v.x, v.y, v.z],
            # IEEE 754 bit patterns, so the receiver can check the doubles bit for bit.
            "vector_bits": [struct.unpack("<Q", struct.pack("<d", x))[0] for x in (v.x, v.y, v.z)],
        }
    if kind == "diagnostics":
        return {
            "header": header(m.header),
            "status": [
                {
                    "level": s.level,
                    "name": s.name,
                    "message": s.message,
                    "hardware_id": s.hardware_id,
                    "values": {kv.key: kv.value for kv in s.values},
                }
                for s in m.status
            ],
        }
    if kind == "image_raw":
        return {
            "header": header(m.header),
            "height": m.height,
            "width": m.width,
            "encoding": m.encoding,
            "is_bigendian": m.is_bigendian,
            "step": m.step,
            "data_hex": bytes(m.data).hex(),
        }
    if kind == "discovery":
        return {
            "gid": bytes(m.gid.data).hex(),
            "nodes": [
                {
                    "namespace": n.node_namespace,
                    "name": n.node_name,
                    "writers": [bytes(g.data).hex() for g in n.writer_gid_seq],
                    "readers": [bytes(g.data).hex() for g in n.reader_gid_seq],
                }
                for n in m.node_entities_info_seq
            ],
        }
    raise ValueError(kind)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--namespace", default="/omnirow")
    ap.add_argument("--timeout", type=float, default=30.0)
    ap.add_argument(
        "--reliable",
        action="store_true",
        help="request reliable delivery on the per-frame topics (matches only a reliable writer)",
    )
    ap.add_argument(
        "--want",
        action="append",
        default=[],
        metavar="KIND=N",
        help="orientation, heading_tilt, row_pose, row_path, row_offset, row_heading_error, "
        "diagnostics, image_raw or discovery",
    )
    args = ap.parse_args()

    ns = "" if args.namespace == "/" else args.namespace
    topics = {
        "orientation": (f"rt{ns}/orientation", Imu_),
        "heading_tilt": (f"rt{ns}/heading_tilt", Vector3Stamped_),
        "image_raw": (f"rt{ns}/image_raw", Image_),
        "row_pose": (f"rt{ns}/row_pose", PoseWithCovarianceStamped_),
        "row_path": (f"rt{ns}/row_path", Path_),
        "row_offset": (f"rt{ns}/row_offset", Float32_),
        "row_heading_error": (f"rt{ns}/row_heading_error", Float32_),
        "diagnostics": ("rt/diagnostics", DiagnosticArray_),
        "discovery": ("ros_discovery_info", ParticipantEntitiesInfo_),
    }
    want = {}
    for w in args.want:
        kind, _, n = w.partition("=")
        if kind not in topics or not n.isdigit():
            print(f"subscribe.py: bad --want {w!r}", file=sys.stderr)
            return 2
        want[kind] = int(n)

    frame_rel = (
        Policy.Reliability.Reliable(duration(seconds=1))
        if args.reliable
        else Policy.Reliability.BestEffort
    )
    qos = {
        "orientation": Qos(frame_rel, Policy.History.KeepLast(50)),
        "heading_tilt": Qos(frame_rel, Policy.History.KeepLast(50)),
        "image_raw": Qos(frame_rel, Policy.History.KeepLast(10)),
        "row_pose": Qos(frame_rel, Policy.History.KeepLast(50)),
        "row_path": Qos(frame_rel, Policy.History.KeepLast(50)),
        "row_offset": Qos(frame_rel, Policy.History.KeepLast(50)),
        "row_heading_error": Qos(frame_rel, Policy.History.KeepLast(50)),
        "diagnostics": Qos(
            Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10)
        ),
        # Latched: the node's announcement arrives however late we join.
        "discovery": Qos(
            Policy.Reliability.Reliable(duration(seconds=1)),
            Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
        ),
    }

    dp = DomainParticipant(args.domain)
    readers = {}
    for kind in want:
        name, typ = topics[kind]
        readers[kind] = DataReader(dp, Topic(dp, name, typ), qos=qos[kind])
    got = {k: 0 for k in want}
    print(json.dumps({"ready": True}), flush=True)

    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline:
        for kind, r in readers.items():
            for m in r.take(N=100):
                if not isinstance(m, topics[kind][1]):
                    continue  # a disposed/unregistered instance notification
                got[kind] += 1
                print(json.dumps({"kind": kind, "msg": decode(kind, m)}), flush=True)
        if all(got[k] >= n for k, n in want.items()):
            return 0
        time.sleep(0.02)
    missing = {k: f"{got[k]}/{n}" for k, n in want.items() if got[k] < n}
    print(f"subscribe.py: timed out after {args.timeout}s; received {missing}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
