"""Warp kernels, grouped by concern. Each group is a :class:`Registry` of factories: ``name -> factory``.

A factory takes plain settings, builds its kernel (specialised with closures / ``wp.static``) and returns
a small callable object that owns its launch. Every entry has a numpy twin in ``irmcl_warp/reference``
and a parity test. Callers ask the registry once and never branch on names.
"""

from irmcl_warp.kernels.registry import (
    ESTIMATE,
    MAPPING,
    MOTION,
    RAYCAST,
    REDUCE_THREADS,
    RENDER,
    RESAMPLE,
    SIM,
    SLAM,
    WEIGHTING,
    Registry,
    init_warp,
    launch_reduction,
    reduction_threads,
    pick_device,
)

__all__ = [
    "ESTIMATE",
    "MAPPING",
    "MOTION",
    "RAYCAST",
    "REDUCE_THREADS",
    "RENDER",
    "RESAMPLE",
    "SIM",
    "SLAM",
    "WEIGHTING",
    "Registry",
    "init_warp",
    "launch_reduction",
    "reduction_threads",
    "pick_device",
]

# importing the families registers their entries
from irmcl_warp.kernels import camera, estimate, mapping, motion, raycast, render, resample, sim, slam, weighting  # noqa: E402,F401,I001
