#!/usr/bin/env python3
"""An independent ROS 2 odometry source: Eclipse Cyclone DDS (the `cyclonedds` wheel), no ROS.

Publishes nav_msgs/Odometry (IDL written here from the ROS 2 message definitions, the
shared types from subscribe.py beside it) with a constant forward speed and yaw rate, as a
robot's wheel odometry would, with ROS 2's default QoS (reliable, keep last 10), at --rate Hz
for --seconds, then exits 0. Prints {"ready": true} once its writer exists.

    publish_odometry.py --domain 17 --topic rt/odom --speed 1.25 --yaw-rate 0.1
"""

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from subscribe import Header_, PoseWithCovariance_, Pose_, Point_, Quaternion_, Time_, Vector3_  # noqa: E402
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl import types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Twist_(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3_
    angular: Vector3_


@dataclass
class TwistWithCovariance_(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist_
    covariance: t.array[t.float64, 36]


@dataclass
class Odometry_(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header_
    child_frame_id: str
    pose: PoseWithCovariance_
    twist: TwistWithCovariance_


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--topic", default="rt/odom", help="DDS topic name (rt/ + the ROS name)")
    ap.add_argument("--speed", type=float, required=True, help="twist.linear.x, m/s")
    ap.add_argument("--yaw-rate", type=float, default=0.0, help="twist.angular.z, rad/s")
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--seconds", type=float, default=30.0)
    args = ap.parse_args()

    dp = DomainParticipant(args.domain)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    w = DataWriter(dp, Topic(dp, args.topic, Odometry_), qos=qos)
    print(json.dumps({"ready": True}), flush=True)
    x = 0.0
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        now = time.time_ns()
        x += args.speed / args.rate
        m = Odometry_(
            header=Header_(
                stamp=Time_(sec=now // 1_000_000_000, nanosec=now % 1_000_000_000),
                frame_id="odom",
            ),
            child_frame_id="base_link",
            pose=PoseWithCovariance_(
                pose=Pose_(
                    position=Point_(x=x, y=0.0, z=0.0),
                    orientation=Quaternion_(x=0.0, y=0.0, z=0.0, w=1.0),
                ),
                covariance=[0.0] * 36,
            ),
            twist=TwistWithCovariance_(
                twist=Twist_(
                    linear=Vector3_(x=args.speed, y=0.0, z=0.0),
                    angular=Vector3_(x=0.0, y=0.0, z=args.yaw_rate),
                ),
                covariance=[0.0] * 36,
            ),
        )
        w.write(m)
        time.sleep(1.0 / args.rate)
    return 0


if __name__ == "__main__":
    sys.exit(main())
