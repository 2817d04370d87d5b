"""The registries (one per concern: name -> factory), Warp's start and the device choice. The kernel families
import these from here; ``kernels/__init__.py`` re-exports them and imports the families, which registers them."""

from __future__ import annotations

import os

import warp as wp


def _quiet() -> None:
    """Warp's start-up banner and module-load lines only with IRMCL_WARP_VERBOSE=1 (Warp 1.19 reads
    ``log_level``; older releases ``quiet``)."""
    verbose = os.environ.get("IRMCL_WARP_VERBOSE", "0") == "1"
    wp.config.quiet = not verbose
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_INFO if verbose else wp.LOG_WARNING


_quiet()


class Registry:
    def __init__(self, concern: str):
        self.concern, self._factories = concern, {}

    def register(self, name: str):
        def deco(factory):
            if name in self._factories:
                raise ValueError(f"{self.concern}: {name!r} registered twice")
            self._factories[name] = factory
            return factory
        return deco

    def build(self, name: str, **settings):
        if name not in self._factories:
            raise KeyError(f"{self.concern}: unknown kernel {name!r}; choose one of {sorted(self._factories)}")
        return self._factories[name](**settings)

    def names(self) -> list[str]:
        return sorted(self._factories)


_initialised = False


def init_warp() -> None:
    global _initialised
    if not _initialised:
        _quiet()
        wp.init()
        _initialised = True


def pick_device(requested: str = "auto") -> str:
    """``"cuda:0"`` when Warp sees a GPU, else ``"cpu"``; any explicit name (``device=cpu``) wins."""
    init_warp()
    if requested in (None, "", "auto"):
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    return requested


REDUCE_THREADS = 4096  # threads of a reduction launch (see launch_reduction)


def launch_reduction(kernel, n: int, inputs: list, device: str) -> None:
    """Launch a reduction over n items on min(n, REDUCE_THREADS) threads; the kernel's last argument is the
    stride: thread t accumulates items t, t + stride, ... in registers and then makes one atomic add per
    output. (One atomic per item on one address serialises: 8 sums over 1M particles cost ~20 ms on an
    H100, measured by eval.bench mcl.)"""
    threads = max(1, min(int(n), REDUCE_THREADS))
    wp.launch(kernel, threads, [*inputs, threads], device=device)


RAYCAST = Registry("raycast")
MAPPING = Registry("mapping")
SIM = Registry("sim")
RENDER = Registry("render")
WEIGHTING = Registry("weighting")
MOTION = Registry("motion")
RESAMPLE = Registry("resample")
ESTIMATE = Registry("estimate")
SLAM = Registry("slam")
