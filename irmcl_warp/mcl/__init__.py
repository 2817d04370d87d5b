"""Monte Carlo localization on Warp kernels (IR-MCL observation model on the NOG)."""

from irmcl_warp.config import MCLConfig
from irmcl_warp.mcl.filter import ParticleFilter

__all__ = ["MCLConfig", "ParticleFilter"]
