"""One factory for the particle filter: ``build_filter(mcl, free_space, laser, far_m, device, maps)``.

Every user of MCL (the localize stage, the pipeline, global localization, the benchmarks) builds its filter
here, from the ``mcl`` config and a map:

* ``free_space``: where particles may start (``free_space_view`` of an occupancy grid);
* ``WeightingMaps``: what the observation model reads: a NOG (``nog_raymarch``), a NOF model
  (``nof_direct``) or an occupancy grid (``likelihood_field``, ``beam_model``).

The weighting is sized by the filter (particles x chosen beams): the filter calls the returned
``make_weighting(num_particles, num_beams)`` once at start and again in ``reduce()``, which releases the
scratch arrays sized for the larger set.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from irmcl_warp.mcl.filter import ParticleFilter
from irmcl_warp.nog import NOG
from irmcl_warp.kernels import WEIGHTING, pick_device
from irmcl_warp.kernels.weighting import NogTable
from irmcl_warp.services.table_cache import cached_table

FREE_BELOW_P = 0.35  # a known cell under this p_occ is free space for the particles' uniform start
NOF_WEIGHTINGS = ("nog_raymarch", "nog_table", "nof_direct")  # the observation models that read the trained field


def free_space_view(probability: np.ndarray, origin_xy, resolution_m: float, known: np.ndarray | None = None) -> NOG:
    """The grid's known free cells (p_occ < FREE_BELOW_P) as 0, the rest 1, in a NOG whose nodes sit at the
    cell centres (``origin_xy``: the grid's lower-left corner): the filter spreads its uniform start over the
    zeros."""
    free = probability < FREE_BELOW_P
    if known is not None:
        free &= known
    centre = (origin_xy[0] + resolution_m / 2, origin_xy[1] + resolution_m / 2)
    return NOG(np.where(free, 0.0, 1.0).astype(np.float32), centre, resolution_m)


@dataclass
class WeightingMaps:
    """What an observation model reads; only the one ``mcl.weighting`` names needs to be set."""

    nog: NOG | None = None  # nog_raymarch, nog_table
    model: object | None = None  # nof_direct: a NOF (torch module)
    occupancy: np.ndarray | None = None  # grid models: p_occ per cell (unknown cells as the model wants them)
    origin_xy: tuple[float, float] | None = None  # ... the grid's lower-left corner
    resolution_m: float | None = None
    built: dict = field(default_factory=dict)  # device arrays made from these maps once (nog_table's table), kept
    # for the filter's next make_weighting (reduce() resizes the scratch, not the map)


def grid_maps(grid, weighting: str) -> WeightingMaps:
    """What AMCL's grid models read from an occupancy grid: unknown cells stop the beam model's rays (AMCL's
    map_calc_range), but are no obstacle for the likelihood field, whose distance map counts occupied cells
    only (as AMCL's)."""
    unknown_as = 0.0 if weighting == "likelihood_field" else 1.0
    occupancy = np.where(grid.known, grid.probability, unknown_as).astype(np.float32)
    return WeightingMaps(occupancy=occupancy, origin_xy=grid.origin_xy, resolution_m=grid.resolution_m)


def make_weighting(mcl, far_m: float, device: str, maps: WeightingMaps, num_particles: int, num_beams: int):
    """The WEIGHTING entry ``mcl.weighting`` for ``num_particles`` x ``num_beams``."""
    w = mcl.weighting
    if w in NOF_WEIGHTINGS:
        shared = dict(
            num_particles=num_particles,
            num_beams=num_beams,
            num_samples=mcl.num_samples,
            near_m=mcl.near_m,
            far_m=far_m,
            sigma_m=mcl.sigma_m,
            device=device,
        )
        if w == "nof_direct":
            import irmcl_warp.nof.direct  # noqa: F401  (registers nof_direct; lazy: it needs torch)

            return WEIGHTING.build(w, model=_need(maps.model, w, "a NOF model"), **shared)
        if w == "nog_table":
            nog = _need(maps.nog, w, "a NOG")
            march = nog_table_settings(mcl, far_m)
            dev = pick_device(device)
            key = ("nog_table", *march.values(), dev)
            if key not in maps.built:  # one table at a time in memory; on disk, one per map and settings
                maps.built = {key: cached_table(nog, march, dev, lambda: NogTable.build(nog, device=dev, **march))}
            return WEIGHTING.build(
                w,
                nog=nog,
                num_angles=mcl.table_angles,
                t_min=mcl.t_min,
                empty_below=mcl.empty_below,
                table=maps.built[key],
                cpu_threads=mcl.cpu_threads,
                **shared,
            )
        return WEIGHTING.build(
            w,
            nog=_need(maps.nog, w, "a NOG"),
            t_min=mcl.t_min,
            empty_below=mcl.empty_below,
            batch=mcl.march_batch,
            beam_major=_march_order(mcl.march_order),
            **shared,
        )
    grid = dict(
        occupancy=_need(maps.occupancy, w, "an occupancy grid"),
        origin_xy=maps.origin_xy,
        resolution_m=maps.resolution_m,
        far_m=far_m,
        z_hit=mcl.z_hit,
        z_rand=mcl.z_rand,
        sigma_hit_m=mcl.sigma_hit_m,
        device=device,
    )
    if w == "likelihood_field":
        return WEIGHTING.build(
            w,
            max_dist_m=mcl.field_max_dist_m,
            occ_threshold=mcl.field_occ_threshold,
            cpu_threads=mcl.cpu_threads,
            **grid,
        )
    if w == "beam_model":
        return WEIGHTING.build(
            w,
            z_short=mcl.z_short,
            z_max=mcl.z_max,
            lambda_short=mcl.lambda_short,
            occ_threshold=mcl.beam_occ_threshold,
            cpu_threads=mcl.cpu_threads,
            **grid,
        )
    return WEIGHTING.build(w, **grid)


def nog_table_settings(mcl, far_m: float) -> dict:
    """The march settings a ``nog_table`` range table is built from (and named by, on disk)."""
    return dict(
        num_angles=mcl.table_angles,
        num_samples=mcl.num_samples,
        near_m=mcl.near_m,
        far_m=far_m,
        t_min=mcl.t_min,
        empty_below=mcl.empty_below,
    )


def _march_order(order: str) -> bool:
    if order not in ("particle", "beam"):
        raise ValueError(f"mcl.march_order={order!r}; choose particle or beam")
    return order == "beam"


def _need(value, weighting: str, what: str):
    if value is None:
        raise ValueError(f"mcl.weighting={weighting} reads {what}, and none was given")
    return value


def build_filter(
    mcl, free_space: NOG, T_base_laser, scan_angles_rad, far_m: float, device: str, maps: WeightingMaps
) -> ParticleFilter:
    """The particle filter of ``mcl`` on this map, its weighting sized by the filter."""
    return ParticleFilter(
        free_space, mcl, T_base_laser, scan_angles_rad, far_m, partial(make_weighting, mcl, far_m, device, maps), device
    )
