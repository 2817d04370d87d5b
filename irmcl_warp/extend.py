"""Extension points: your own observation model or SLAM proposal, from a file of your own, chosen by config.

Write a file (anywhere; nothing in this package changes) that registers a factory under a new name, then name the
file in ``plugins`` and choose the name as you would a built-in one::

    python -m irmcl_warp.localize plugins=[my_model.py] mcl.weighting=my_model ...
    python -m irmcl_warp.slam plugins=[my_proposal.py] slam.proposal=my_proposal ...

``plugins`` takes .py files (relative to where you run) or importable module names; they are imported before the
settings are checked, so a name they register is a valid choice from then on. tests/plugins/ holds a working
example of each kind, run through localize and slam by tests/test_extend.py.

* **Observation model** (``mcl.weighting``): register a factory in ``irmcl_warp.kernels.WEIGHTING``. A name that
  is not one of the NOF weightings is built with the occupancy grid's settings (``GridSettings``) and returns an
  ``ObservationModel``.
* **SLAM proposal** (``slam.proposal``): register a factory in ``irmcl_warp.slam.rbpf.PROPOSALS``. It is called
  once with the filter (``RBPF``) and returns a ``Proposal``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Protocol, TypedDict, runtime_checkable

import numpy as np


class GridSettings(TypedDict):
    """What a grid-based observation model's factory is called with (services/filters.make_weighting)."""

    occupancy: np.ndarray  # p_occ per cell [H, W], row 0 at origin_xy's y
    origin_xy: tuple  # the grid's lower-left corner (m)
    resolution_m: float
    far_m: float  # the sensor's far bound
    z_hit: float  # mcl.z_hit, mcl.z_rand, mcl.sigma_hit_m: the mixture a model may use
    z_rand: float
    sigma_hit_m: float
    device: str  # the Warp device of the filter's arrays


@runtime_checkable
class ObservationModel(Protocol):
    """Scores every particle's pose against one scan: ``log_weights[p] = log p(scan | pose p)`` (up to a constant).
    The arrays are Warp arrays on the filter's device: particles [P] vec3 (x, y, yaw in the map), angles [B] and
    measured [B] (m, NaN where a beam returned nothing), log_weights [P] to be filled."""

    capturable: bool  # True only if __call__ launches Warp kernels alone (a GPU step may then replay it as a graph)

    def __call__(self, particles, T_base_laser, angles, measured, log_weights) -> None: ...


@runtime_checkable
class Proposal(Protocol):
    """GMapping's proposal step for every particle: from the poses sampled by the motion model and the odometry
    moved since the last processed scan, the new poses [P, 3], each particle's log-weight gain [P] and the scan
    matcher's rounds (0 if it did not match). The filter (``RBPF``) offers ``loglik_at(poses [P, K, 3])``, the
    scan's log-likelihood in each particle's own map, and ``match(poses)``, the hill-climbing scan matcher."""

    def __call__(self, sampled: np.ndarray, moved: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]: ...


def load_plugins(names) -> list:
    """Import each plugin (a .py file or a module name), once; an error names the plugin and what went wrong."""
    loaded = []
    for name in names or []:
        name = str(name)
        if name.endswith(".py"):
            path = Path(name).expanduser().resolve()
            if not path.is_file():
                raise FileNotFoundError(f"plugins: {name}: no such file (from {Path.cwd()})")
            module_name = f"irmcl_plugin_{path.stem}"
            if module_name in sys.modules and getattr(sys.modules[module_name], "__file__", None) == str(path):
                loaded.append(sys.modules[module_name])
                continue
            spec = importlib.util.spec_from_file_location(module_name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[module_name] = module
            try:
                spec.loader.exec_module(module)
            except Exception:
                del sys.modules[module_name]
                raise
            loaded.append(module)
        else:
            try:
                loaded.append(importlib.import_module(name))
            except ModuleNotFoundError as e:
                raise ValueError(f"plugins: {name!r} is neither a .py file nor an importable module ({e})") from e
    return loaded
