"""Bring a log of another format in: a template that turns arrays into a ROS 1 bag this toolkit (and ROS) reads.

Fill ``load_your_log`` with your own reader; the rest stays. The arrays, per scan i of N with B beams each:

    stamps[i]         seconds (any epoch), increasing
    ranges[i, b]      metres; NaN (or inf) where the beam saw nothing; beam b points at angle_min + b * increment
                      in the laser's frame (counter-clockwise, x forward; a clockwise scanner: reverse each row)
    odom[i]           the odometry's pose of the base at stamps[i]: x, y (m), yaw (rad), in the odometry's frame
    T_base_laser      the laser's pose on the base: x, y (m), yaw (rad)

    python examples/convert_to_bag.py mylog.npz mylog.bag
    irmcl-warp inspect data=bag data.path=mylog.bag data.name=mylog      # the checker: what it holds, what looks wrong

An .npz with arrays ``stamps``, ``ranges``, ``odom`` and scalars ``angle_min``, ``angle_increment``, ``range_min``,
``range_max`` (and optionally ``T_base_laser``) works as it is.
"""

from __future__ import annotations

import sys

import numpy as np

from irmcl_warp.io import write_bag
from irmcl_warp.types import LaserInfo, LaserLog


def load_your_log(path: str) -> dict:
    """Your reader goes here; this one reads the .npz described above."""
    z = np.load(path)
    return {k: z[k] for k in z.files}


def to_log(a: dict, source: str) -> LaserLog:
    ranges = np.asarray(a["ranges"], np.float32)
    ranges = np.where(np.isfinite(ranges), ranges, np.nan).astype(np.float32)
    info = LaserInfo(
        num_beams=ranges.shape[1],
        angle_min_rad=float(a["angle_min"]),
        angle_increment_rad=float(a["angle_increment"]),
        range_min_m=float(a["range_min"]),
        range_max_m=float(a["range_max"]),
        no_return_m=float(a["range_max"]),
    )
    return LaserLog(
        stamps=np.asarray(a["stamps"], np.float64),
        ranges_m=ranges,
        odom=np.asarray(a["odom"], np.float64),
        info=info,
        T_base_laser=np.asarray(a.get("T_base_laser", np.zeros(3)), np.float64),
        source=source,
    )


def main(argv: list[str]) -> None:
    if len(argv) != 2:
        raise SystemExit("usage: python examples/convert_to_bag.py <your log> <out.bag>")
    log = to_log(load_your_log(argv[0]), argv[0])  # LaserLog checks shapes and finite stamps/odometry
    print(f"wrote {write_bag(log, argv[1])}: {len(log.stamps)} scans of {log.info.num_beams} beams")


if __name__ == "__main__":
    main(sys.argv[1:])
