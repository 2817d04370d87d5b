"""``python -m eval.analyses.twins RUN_DIR [--out F.json]``: could the drives of a worlds run on twin floors be told
from their turned twins at all, by the run's own observation model in the run's own map? (issue 33)

A twin floor's walls repeat after a half turn about its centre; only its furniture (a box in some rooms) tells the
halves apart. For every drive of the run on a twin floor this recomputes the map and the drive from their seeds and
sums, over the scans the run updated on, the run's tempered likelihood field (mcl.* settings: z_hit, z_rand,
sigma_hit, the beams it picks, temper) at the true poses less at the true poses turned about the floor's centre:
``evidence`` > 0 where the scans favour the truth. A drive whose evidence is near 0 or negative cannot be told from
its twin by this model and map (the filter then ends on either; a wrong end there is not the filter's doing), and
its confidence cannot be high and right: a calibrated 0.5 is the best it can say.

Prints a table (drive, evidence, where the run ended: right, at the twin, elsewhere; its confidence at the end) and
writes it as JSON."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.kernels import init_warp
from irmcl_warp.kernels.raycast import distance_to_occupied
from irmcl_warp.mcl.confidence import right
from irmcl_warp.mcl.filter import pick_beams
from irmcl_warp.mcl.worlds import query_log, world_map
from irmcl_warp.reference.weighting import likelihood_field_log_weights
from irmcl_warp.services.filters import grid_maps
from irmcl_warp.services.outputs import write_json
from irmcl_warp.sim import floors

TWIN_M = 0.5  # a run "ended at the twin" within this of the true pose turned about the floor's centre


def turned(world, poses: np.ndarray) -> np.ndarray:
    """``poses`` [n, 3] turned half about the floor's centre: where a twin floor's walls look the same."""
    p = np.asarray(poses, float)
    return np.column_stack(
        [world.width_m - p[:, 0], world.height_m - p[:, 1], np.angle(np.exp(1j * (p[:, 2] + np.pi)))]
    )


def drive_evidence(world, cfg, k: int, updated: np.ndarray, grid=None, device: str = "cpu") -> dict:
    """{"evidence": tempered log-likelihood of drive ``k``'s true poses less of the turned ones, summed over the
    scans where ``updated``; "per_update": its mean; "updates"}."""
    m = cfg.mcl
    grid = world_map(world, cfg, device) if grid is None else grid
    maps = grid_maps(grid, "likelihood_field")
    dist = distance_to_occupied(maps.occupancy, maps.resolution_m, m.field_occ_threshold)
    log, _ = query_log(world, cfg, k, device)
    beams = pick_beams(log.ranges_m.shape[1], m.num_beams, m.beam_pick)
    angles = log.info.angles_rad[beams]
    far_m = cfg.sim.range_max_m
    total = 0.0
    idx = np.flatnonzero(updated[: len(log.stamps)])
    for i in idx:
        z = log.ranges_m[i, beams].astype(float)
        z = np.where((z > m.near_m) & (z < far_m), z, np.nan)
        both = np.vstack([log.ground_truth[i], turned(world, log.ground_truth[i][None])[0]])
        ll = likelihood_field_log_weights(
            dist,
            maps.origin_xy,
            maps.resolution_m,
            both,
            log.T_base_laser,
            angles,
            z,
            m.z_hit,
            m.z_rand,
            m.sigma_hit_m,
            far_m,
            m.field_max_dist_m,
        )
        total += m.temper * float(ll[0] - ll[1])
    return {"evidence": total, "per_update": total / max(len(idx), 1), "updates": int(len(idx))}


def twins(run_dir: Path, device: str = "cpu") -> dict:
    init_warp()
    run_dir = Path(run_dir)
    cfg = OmegaConf.load(run_dir / "config.yaml")
    doc = json.loads((run_dir / "metrics.json").read_text())
    rows = []
    names = sorted({r["world"] for r in doc["runs"] if floors.parse(r["world"])[0] == "twin"})
    for name in names:
        world = floors.build(name)
        grid = world_map(world, cfg, device)
        for r in [r for r in doc["runs"] if r["world"] == name]:
            z = np.load(run_dir / f"{name}-run{r['run']}.npz")
            e = drive_evidence(world, cfg, r["run"], z["updated"], grid, device)
            est, gt = z["estimate"][-1], z["truth"][-1]
            at_twin = bool(np.all(np.isfinite(est)) and right(est[None], turned(world, gt[None]))[0])
            rows.append(
                {
                    "world": name,
                    "run": r["run"],
                    **e,
                    "right_at_end": bool(r["right_at_end"]),
                    "at_twin_at_end": at_twin,
                    "confidence_at_end": r["confidence_at_end"],
                }
            )
    return {"run": run_dir.name, "device": doc["summary"].get("device"), "drives": rows}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    res = twins(a.run, a.device)
    print("| drive | evidence for the truth over its twin (tempered log-lik.) | ended | confidence at end |")
    print("|---|---|---|---|")
    for r in res["drives"]:
        ended = "right" if r["right_at_end"] else ("at the twin" if r["at_twin_at_end"] else "elsewhere")
        conf = "-" if r["confidence_at_end"] is None else f"{r['confidence_at_end']:.2f}"
        print(f"| {r['world']} run {r['run']} | {r['evidence']:+.1f} | {ended} | {conf} |")
    if a.out:
        write_json(a.out, res)
        print(f"-> {a.out}")
    return res


if __name__ == "__main__":
    main()
