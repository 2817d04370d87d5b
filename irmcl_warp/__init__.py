"""irmcl-warp: 2D-LiDAR localization and mapping on NVIDIA Warp kernels.

Stages (see docs/ARCHITECTURE.md): io -> mapping / slam -> train (NOF) -> nog -> localize -> eval.
"""

__version__ = "0.1.0"
