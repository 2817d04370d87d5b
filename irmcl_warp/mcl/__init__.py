"""Monte Carlo localization on Warp kernels (IR-MCL observation model on the NOG)."""

from irmcl_warp.mcl.filter import MCLConfig, ParticleFilter

__all__ = ["MCLConfig", "ParticleFilter"]
