"""``python -m eval.analyses.determinism [--seeds 5] [--device cuda:0]``: do MCL runs on one device repeat bit for bit?

For each weighting (``nog_raymarch``, ``likelihood_field``) and seed, the simulator's log is filtered three
times: eager, as one captured graph per step, and eager again (600 particles, reduced to 300 halfway, as in
tests/test_mcl.py). Prints how many seeds gave the same estimates bit for bit, graph against eager and eager
against eager, and the largest position difference. On the CPU every thread runs in order, so all agree;
on a GPU, sums that threads add atomically can differ in their last bits from run to run.
"""

from __future__ import annotations

import argparse

import numpy as np

from eval.bench.mcl import simulator_nog
from irmcl_warp.config import compose_config
from irmcl_warp.mcl import MCLConfig
from irmcl_warp.services.cli import guard
from irmcl_warp.services.filters import WeightingMaps, build_filter
from irmcl_warp.sim import simulate
from irmcl_warp.kernels import pick_device
from irmcl_warp.kernels.motion import odometry_step


def run(log, nog, maps, weighting: str, seed: int, graph: str, device: str, **settings):
    """One filter run over the log: 600 particles around the first true pose, reduced to 300 halfway (a
    reduce() reallocates what a graph was captured on); ``settings``: more MCLConfig fields. (estimates [K, 3],
    N_eff [K], the filter)."""
    cfg = MCLConfig(num_particles=600, num_samples=64, seed=seed, weighting=weighting, step_graph=graph, **settings)
    pf = build_filter(cfg, nog, log.T_base_laser, log.info.angles_rad, 10.0, device, maps)
    pf.init_gaussian(log.ground_truth[0], (0.3, 0.3, 0.1))
    out = []
    for k in range(1, len(log)):
        if k == len(log) // 2:
            pf.reduce(300)
        out.append(pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k]))
    return np.array([o[0] for o in out]), np.array([o[1] for o in out]), pf


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.determinism")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--device", default="auto")
    a = ap.parse_args(argv)
    device = pick_device(a.device)
    log, _ = simulate(compose_config(["sim.duration_s=4"]).sim, device)
    nog = simulator_nog(0.1, device)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.occupancy, origin_xy=corner, resolution_m=nog.resolution_m)
    report = {}
    for weighting in ("nog_raymarch", "likelihood_field"):
        same_graph = same_eager = 0
        worst = 0.0
        for seed in range(a.seeds):
            eager, graph, again = (run(log, nog, maps, weighting, seed, g, device)[0] for g in ("off", "on", "off"))
            same_graph += np.array_equal(eager, graph)
            same_eager += np.array_equal(eager, again)
            worst = max(
                worst,
                float(np.abs(eager[:, :2] - graph[:, :2]).max()),
                float(np.abs(eager[:, :2] - again[:, :2]).max()),
            )
        report[weighting] = {
            "graph_equals_eager": same_graph,
            "eager_equals_eager": same_eager,
            "seeds": a.seeds,
            "largest_position_difference_m": worst,
        }
        print(
            f"{device} {weighting}: graph == eager bit for bit in {same_graph}/{a.seeds} seeds, eager == eager "
            f"in {same_eager}/{a.seeds}; largest position difference {worst:.2e} m"
        )
    return report


if __name__ == "__main__":
    guard(main)
