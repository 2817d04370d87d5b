"""A localization run as an MCAP file (ROS 2 message types) to open in Foxglove Studio or replay into RViz:
``write_run_mcap(path, ...)``.

Topics, in the map frame unless said:

    /map             nav_msgs/OccupancyGrid            once, transient local (latched)
    /scan            sensor_msgs/LaserScan             every scan of the run (frame laser)
    /odom            nav_msgs/Odometry                 every scan (frame odom)
    /tf              tf2_msgs/TFMessage                odom -> base_link at every scan, map -> odom where there is
                                                       an estimate (what AMCL broadcasts)
    /tf_static       tf2_msgs/TFMessage                base_link -> laser, transient local
    /amcl_pose       geometry_msgs/PoseWithCovarianceStamped   the estimate at every scan that has one (the
                                                       particles' covariance at updates, where it was kept)
    /particlecloud   geometry_msgs/PoseArray           the particles at some scans (decimated, as the animation)
    /ground_truth    geometry_msgs/PoseStamped         the truth in the map frame, where the log has it
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irmcl_warp.geometry import compose, inverse
from irmcl_warp.io.rosbag import ODOM, SCAN, TF, Messages, add_connection, bag_writer

GRID, POSE_COV, POSE_ARRAY, POSE = (
    "nav_msgs/msg/OccupancyGrid",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/PoseArray",
    "geometry_msgs/msg/PoseStamped",
)
TOPICS = ("/map", "/scan", "/odom", "/tf", "/tf_static", "/amcl_pose", "/particlecloud", "/ground_truth")


def write_run_mcap(
    path,
    *,
    log,
    idx: np.ndarray,
    est: np.ndarray,
    grid,
    map_data: np.ndarray,
    covariances=None,
    particle_frames=(),
    ground_truth_in_map: np.ndarray | None = None,
    map_frame="map",
    odom_frame="odom",
    base_frame="base_link",
    laser_frame="laser",
) -> Path:
    """The run over the scans ``idx`` of ``log`` with its estimates ``est`` [len(idx), 3] (NaN: none yet) as an MCAP
    at ``path`` (written whole, then renamed). ``grid``: the map (shape, origin_xy, resolution_m), ``map_data``
    its OccupancyGrid values [H, W] (mapping.mapio.occupancy_data);
    ``covariances``: [len(idx), 3, 3] or None (NaN rows: not an update); ``particle_frames``: (scan position j,
    particles [n, 3]) pairs; ``ground_truth_in_map`` [len(idx), 3] or None."""
    path = Path(path)
    m = Messages(2)
    T, ser = m.T, m.serialize
    stamps = log.stamps[idx]
    writer, finish, discard = bag_writer(path.with_suffix(""), 2, "mcap")
    try:
        with writer:
            c = {
                topic: add_connection(writer, m, topic, msgtype, latched=topic in ("/map", "/tf_static"))
                for topic, msgtype in zip(TOPICS, (GRID, SCAN, ODOM, TF, TF, POSE_COV, POSE_ARRAY, POSE))
            }
            t0 = float(stamps[0])
            ns0 = int(round(t0 * 1e9))
            H, W = grid.shape
            info = T["nav_msgs/msg/MapMetaData"](
                map_load_time=m.header(t0, map_frame).stamp,
                resolution=float(grid.resolution_m),
                width=W,
                height=H,
                origin=m.pose((grid.origin_xy[0], grid.origin_xy[1], 0.0)),
            )
            writer.write(
                c["/map"],
                ns0,
                ser(
                    T[GRID](header=m.header(t0, map_frame), info=info, data=np.asarray(map_data, np.int8).ravel()), GRID
                ),
            )
            writer.write(c["/tf_static"], ns0, ser(m.tf(t0, base_frame, laser_frame, log.T_base_laser), TF))
            frames = dict(particle_frames)
            for j, i in enumerate(idx):
                stamp, ns, odom = float(stamps[j]), int(round(float(stamps[j]) * 1e9)), log.odom[i]
                writer.write(c["/scan"], ns, ser(m.scan(stamp, log.info, log.ranges_m[i], laser_frame), SCAN))
                writer.write(c["/odom"], ns, ser(m.odom(stamp, odom, 0.0, odom_frame, base_frame), ODOM))
                writer.write(c["/tf"], ns, ser(m.tf(stamp, odom_frame, base_frame, odom), TF))
                if np.all(np.isfinite(est[j])):
                    map_odom = compose(est[j][None], inverse(np.asarray(odom, float)[None]))[0]
                    writer.write(c["/tf"], ns, ser(m.tf(stamp, map_frame, odom_frame, map_odom), TF))
                    cov6 = np.zeros((6, 6))
                    if covariances is not None and np.all(np.isfinite(covariances[j])):
                        cov6[np.ix_([0, 1, 5], [0, 1, 5])] = covariances[j]  # x, y, yaw of ROS's x y z roll pitch yaw
                    pose = T["geometry_msgs/msg/PoseWithCovariance"](pose=m.pose(est[j]), covariance=cov6.ravel())
                    writer.write(
                        c["/amcl_pose"], ns, ser(T[POSE_COV](header=m.header(stamp, map_frame), pose=pose), POSE_COV)
                    )
                if j in frames:
                    poses = [m.pose(p) for p in np.asarray(frames[j], float)]
                    writer.write(
                        c["/particlecloud"],
                        ns,
                        ser(T[POSE_ARRAY](header=m.header(stamp, map_frame), poses=poses), POSE_ARRAY),
                    )
                if ground_truth_in_map is not None and np.all(np.isfinite(ground_truth_in_map[j])):
                    writer.write(
                        c["/ground_truth"],
                        ns,
                        ser(T[POSE](header=m.header(stamp, map_frame), pose=m.pose(ground_truth_in_map[j])), POSE),
                    )
    except BaseException:
        discard()
        raise
    folder = finish()  # a ROS 2 bag folder <name>/ holding <name>.mcap and metadata.yaml
    return folder / f"{folder.name}.mcap"
