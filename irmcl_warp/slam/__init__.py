"""Grid SLAM: GMapping's Rao-Blackwellized particle filter (rbpf.py) and its stage (stage.py)."""

from irmcl_warp.slam.rbpf import RBPF, per_scan_poses  # noqa: F401

__all__ = ["RBPF", "per_scan_poses"]
