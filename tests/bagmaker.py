"""Small ROS1 bags written message by message, for readers' tests that need what write_bag cannot write:
scans with their own geometry, odometry with odd quaternions."""

from __future__ import annotations

import numpy as np

SCAN, ODOM = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"


def scan(stamp, ranges, angle_min=-np.pi / 2, increment=None, range_min=0.1, range_max=30.0, quat=(0, 0, 0, 1)):
    ranges = np.asarray(ranges, np.float32)
    increment = np.pi / (len(ranges) - 1) if increment is None else increment
    return dict(
        stamp=stamp,
        ranges=ranges,
        angle_min=angle_min,
        increment=increment,
        range_min=range_min,
        range_max=range_max,
        quat=quat,
    )


def write_scans(path, scans) -> None:
    """One LaserScan and one Odometry (pose (0.1 k, 0) with the scan's ``quat``) per entry of ``scans``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Vec3, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    with Writer(path) as w:
        c_scan, c_odom = w.add_connection("/scan", SCAN, typestore=ts), w.add_connection("/odom", ODOM, typestore=ts)
        for k, s in enumerate(scans):
            ns = int(round(s["stamp"] * 1e9))
            hdr = Header(seq=k, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="laser")
            n = len(s["ranges"])
            msg = T[SCAN](
                header=hdr,
                angle_min=float(s["angle_min"]),
                angle_max=float(s["angle_min"] + s["increment"] * (n - 1)),
                angle_increment=float(s["increment"]),
                time_increment=0.0,
                scan_time=0.0,
                range_min=float(s["range_min"]),
                range_max=float(s["range_max"]),
                ranges=s["ranges"],
                intensities=np.zeros(0, np.float32),
            )
            w.write(c_scan, ns, ts.serialize_ros1(msg, SCAN))
            x, y, z, qw = (float(v) for v in s["quat"])
            cov = np.zeros(36)
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=0.1 * k, y=0.0, z=0.0),
                    orientation=Quat(x=x, y=y, z=z, w=qw),
                ),
                covariance=cov,
            )
            tw = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=Vec3(x=0.5, y=0.0, z=0.0), angular=Vec3(x=0.0, y=0.0, z=0.0)),
                covariance=cov,
            )
            w.write(
                c_odom,
                ns,
                ts.serialize_ros1(
                    T[ODOM](
                        header=Header(seq=k, stamp=hdr.stamp, frame_id="odom"),
                        child_frame_id="base_link",
                        pose=pose,
                        twist=tw,
                    ),
                    ODOM,
                ),
            )
