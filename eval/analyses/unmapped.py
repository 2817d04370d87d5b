"""``python -m eval.analyses.unmapped [--split test] [--out F.json]``: how much of each drive of the worlds stage lies
outside its floor's map, with each mapping drive (``worlds.map_drive``: ``random``, the maps before the twenty-sixth
session, and ``cover``). Where the map knows nothing, a scan can fit a mapped look-alike room better than the unknown
one the robot is in, and "right at the end" then says little about the localizer (issue 33).

Recomputes the maps and the drives from their seeds (no run needed); prints a table and writes, per map drive and
world, each drive's share of poses on cells its map does not know, and the drives over ``UNMAPPED_WARN``."""

from __future__ import annotations

import argparse

from irmcl_warp.config import compose_config
from irmcl_warp.kernels import init_warp
from irmcl_warp.mcl.worlds import UNMAPPED_WARN, query_log, unmapped_share, world_map, world_names
from irmcl_warp.services.outputs import write_json
from irmcl_warp.sim import floors

MAP_DRIVES = ("random", "cover")


def unmapped(split: str, runs: int, device: str = "cpu") -> dict:
    """{map drive: {world: [share of drive k's poses off the map's known cells, k = 1..runs]}} and the drives over
    UNMAPPED_WARN by name."""
    init_warp()
    out = {"split": split, "runs": runs, "warn_above": UNMAPPED_WARN, "shares": {}, "leaving": {}}
    for how in MAP_DRIVES:
        cfg = compose_config(["+exp=worlds", f"worlds.map_drive={how}", f"worlds.runs={runs}", f"device={device}"])
        shares = {}
        for name in world_names(split):
            world = floors.build(name)
            grid = world_map(world, cfg, device)
            shares[name] = [
                unmapped_share(grid, query_log(world, cfg, k, device)[0].ground_truth) for k in range(1, runs + 1)
            ]
        out["shares"][how] = shares
        out["leaving"][how] = [
            f"{w}-run{k + 1}" for w, v in shares.items() for k, s in enumerate(v) if s > UNMAPPED_WARN
        ]
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", default="test")
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    res = unmapped(a.split, a.runs, a.device)
    print(f"| map drive | world | share of each drive off the map (runs 1-{a.runs}) |\n|---|---|---|")
    for how, shares in res["shares"].items():
        for w, v in shares.items():
            print(f"| {how} | {w} | {' '.join(f'{s:.2f}' for s in v)} |")
    for how, names in res["leaving"].items():
        print(f"{how}: {len(names)} drives leave the map: {', '.join(names) or 'none'}")
    if a.out:
        write_json(a.out, res)
        print(f"-> {a.out}")
    return res


if __name__ == "__main__":
    main()
