"""An example ROS 2 node on the online localizer (irmcl_warp/mcl/online.py): AMCL's interface, our filter.

Runs where rclpy and the message packages exist (a sourced ROS 2 workspace); the toolkit neither needs nor
installs them, and this file is an example, not a supported node. With the package installed:

    python3 examples/ros2_localizer.py --ros-args -p map:=/path/to/map.yaml -p weighting:=likelihood_field \
        -p particles:=5000 -p laser_x:=0.1

Subscribes /scan (sensor_msgs/LaserScan), /odom (nav_msgs/Odometry) and /initialpose (RViz's "2D Pose
Estimate"); publishes /amcl_pose (PoseWithCovarianceStamped, with the particles' covariance) and the map -> odom
transform on /tf. Without an initial pose it localizes globally over the map's free space. The laser's pose
on the base comes from parameters here (laser_x, laser_y, laser_yaw); a real node would read it from tf.
"""

from __future__ import annotations

import math

import numpy as np
import rclpy
from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from tf2_ros import TransformBroadcaster

from irmcl_warp.config import MCLConfig
from irmcl_warp.geometry import compose, inverse
from irmcl_warp.mcl.online import open_localizer


def yaw_of(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def set_yaw(q, yaw: float) -> None:
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


class Localizer(Node):
    def __init__(self):
        super().__init__("irmcl_warp_localizer")
        p = {
            name: self.declare_parameter(name, default).value
            for name, default in [
                ("map", ""),
                ("weighting", "likelihood_field"),
                ("particles", 5000),
                ("device", "auto"),
                ("laser_x", 0.0),
                ("laser_y", 0.0),
                ("laser_yaw", 0.0),
                ("update_min_d", 0.2),
                ("update_min_a", 0.5),
                ("map_frame", "map"),
                ("odom_frame", "odom"),
            ]
        }
        if not p["map"]:
            raise SystemExit("set the map: --ros-args -p map:=/path/to/map.yaml")
        self.p = p
        self.mcl = MCLConfig(
            weighting=p["weighting"],
            num_particles=int(p["particles"]),
            update_min_trans_m=float(p["update_min_d"]),
            update_min_rot_rad=float(p["update_min_a"]),
        )
        self.loc = None  # built on the first scan, which gives the beams' angles and the far bound
        self.initial = None
        self.odom = None  # the latest odometry pose [x, y, yaw] in the odom frame
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, "amcl_pose", 10)
        self.tf = TransformBroadcaster(self)
        self.create_subscription(Odometry, "odom", self.on_odom, 50)
        self.create_subscription(LaserScan, "scan", self.on_scan, 10)
        self.create_subscription(PoseWithCovarianceStamped, "initialpose", self.on_initial_pose, 1)

    def on_odom(self, msg: Odometry) -> None:
        q = msg.pose.pose.orientation
        self.odom = np.array([msg.pose.pose.position.x, msg.pose.pose.position.y, yaw_of(q)])

    def on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        q = msg.pose.pose.orientation
        pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw_of(q))
        if self.loc is None:
            self.initial = pose
        else:
            self.loc.initial_pose(pose)
        self.get_logger().info(f"initial pose {pose}")

    def on_scan(self, msg: LaserScan) -> None:
        if self.odom is None:
            return  # no odometry yet
        ranges = np.asarray(msg.ranges, np.float32)
        ranges[~np.isfinite(ranges) | (ranges < msg.range_min) | (ranges >= msg.range_max)] = np.nan  # no return
        if self.loc is None:
            angles = msg.angle_min + msg.angle_increment * np.arange(len(ranges))
            laser = (self.p["laser_x"], self.p["laser_y"], self.p["laser_yaw"])
            self.loc = open_localizer(
                self.p["map"],
                self.mcl,
                laser,
                angles,
                float(msg.range_max),
                device=self.p["device"],
                initial_pose=self.initial,
            )
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        est = self.loc.update(stamp, ranges, self.odom.copy())
        if not np.all(np.isfinite(est.pose)):
            return  # no estimate before the robot first moves (mcl.first_update=motion)
        self.publish(msg.header.stamp, est)

    def publish(self, stamp, est) -> None:
        out = PoseWithCovarianceStamped()
        out.header.stamp, out.header.frame_id = stamp, self.p["map_frame"]
        out.pose.pose.position.x, out.pose.pose.position.y = float(est.pose[0]), float(est.pose[1])
        set_yaw(out.pose.pose.orientation, float(est.pose[2]))
        if est.covariance is not None and np.all(np.isfinite(est.covariance)):
            cov = np.zeros((6, 6))
            cov[np.ix_([0, 1, 5], [0, 1, 5])] = est.covariance  # x, y, yaw into ROS's 6 x 6 (x y z roll pitch yaw)
            out.pose.covariance = cov.ravel().tolist()
        self.pose_pub.publish(out)
        # map -> odom: the pose in the map composed with the inverse of the odometry's pose
        map_odom = compose(est.pose[None], inverse(self.odom[None]))[0]
        t = TransformStamped()
        t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, self.p["map_frame"], self.p["odom_frame"]
        t.transform.translation.x, t.transform.translation.y = float(map_odom[0]), float(map_odom[1])
        set_yaw(t.transform.rotation, float(map_odom[2]))
        self.tf.sendTransform(t)


def main() -> None:
    rclpy.init()
    node = Localizer()
    try:
        rclpy.spin(node)
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
