"""A localizer in your own map, for a robot: ``open_localizer`` builds the filter on a map file (a map_server
YAML + image, or the slam stage's ``.npz``) and hands back a ``track.Localizer`` fed one scan at a time.

    from irmcl_warp.config import MCLConfig
    from irmcl_warp.mcl.online import open_localizer

    loc = open_localizer("map.yaml", MCLConfig(weighting="likelihood_field", num_particles=5000),
                         T_base_laser=(0.1, 0.0, 0.0), angles_rad=angles, far_m=20.0, initial_pose=(2.0, 1.5, 0.3))
    est = loc.update(stamp, ranges, odom_pose)   # est.pose, est.covariance, est.updated

The offline run in your own map (``localize.map_path``, mcl/own_map.py) builds its filter with ``filter_in_map``
and drives it through the same class, so the two give the same poses (tests/test_online.py). An example ROS 2
node on top of it: examples/ros2_localizer.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irmcl_warp.io import resolve
from irmcl_warp.mapping.mapio import load_map
from irmcl_warp.mcl.track import Localizer
from irmcl_warp.nof.checkpoint import load_nof_for
from irmcl_warp.services.filters import NOF_WEIGHTINGS, WeightingMaps, build_filter, free_space_view, grid_maps
from irmcl_warp.services.nog import bake_nog
from irmcl_warp.kernels import pick_device


def weighting_maps(m, grid, device: str, far_m: float, nof_path=None, nog_cache: Path | None = None) -> WeightingMaps:
    """What the observation model ``m.weighting`` reads: the grid (AMCL's models), or the NOF at ``nof_path``
    (as the torch MLP, or baked into a NOG over the grid's extent, cached in ``nog_cache``)."""
    if m.weighting not in NOF_WEIGHTINGS:
        return grid_maps(grid, m.weighting)
    if not nof_path:
        raise ValueError(f"mcl.weighting={m.weighting} reads a trained NOF: set localize.nof_path=<nof.pt>")
    ckpt = resolve(nof_path)
    torch_device = "cuda" if device.startswith("cuda") else "cpu"
    if m.weighting == "nof_direct":
        return WeightingMaps(model=load_nof_for(ckpt, far_m, torch_device)[0])
    H, W = grid.shape
    x0, y0 = grid.origin_xy
    bounds = (x0, y0, x0 + W * grid.resolution_m, y0 + H * grid.resolution_m)
    return WeightingMaps(
        nog=bake_nog(ckpt, bounds, far_m, m.map_resolution_m, cache_dir=nog_cache, device=torch_device)
    )


def filter_in_map(
    map_file,
    m,
    T_base_laser,
    angles_rad,
    far_m: float,
    device: str = "auto",
    nof_path=None,
    nog_cache: Path | None = None,
):
    """(the particle filter on the map in ``map_file``, the map's grid); its generator seeded by ``m.seed``,
    the particles not yet placed."""
    device = pick_device(device)
    grid = load_map(resolve(map_file))
    view = free_space_view(grid.probability, grid.origin_xy, grid.resolution_m, grid.known)
    pf = build_filter(
        m,
        view,
        T_base_laser,
        np.asarray(angles_rad, float),
        far_m,
        device,
        weighting_maps(m, grid, device, far_m, nof_path, nog_cache),
    )
    pf.rng = np.random.default_rng(m.seed)
    return pf, grid


def open_localizer(
    map_file,
    m,
    T_base_laser,
    angles_rad,
    far_m: float,
    device: str = "auto",
    nof_path=None,
    initial_pose=None,
    initial_std=(0.5, 0.5, 0.3),
    reduce_after_s: float | None = None,
    covariance: bool = True,
    nog_cache: Path | None = None,
) -> Localizer:
    """A ``Localizer`` on ``map_file``: particles around ``initial_pose`` [x, y, yaw] (spread ``initial_std``),
    or over the map's free space where it is None (global localization). ``angles_rad``: the scan's beam angles
    in the laser's frame; ``T_base_laser``: the laser's pose on the base [x, y, yaw]; ``far_m``: a beam at or
    beyond reads no return."""
    pf, _ = filter_in_map(map_file, m, T_base_laser, angles_rad, far_m, device, nof_path, nog_cache)
    loc = Localizer(pf, m, reduce_after_s, covariance=covariance)
    if initial_pose is not None:
        pose = np.asarray(list(initial_pose), np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"initial pose {list(initial_pose)}: expected [x, y, yaw] in the map")
        loc.initial_pose(pose, initial_std)
    else:
        loc.global_start()
    return loc
