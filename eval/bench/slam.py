"""``python -m eval.bench slam [--exp gmapping_sim] [--particles 30] [--device cpu|cuda:0] [--scans N] [--released]``

Wall time of GMapping's RBPF over a whole log (or its first N scans) and the time per processed scan split
into motion (all scans since the last processed one), scan matching, weights + resampling and map
integration, per particle count. Prints a table and writes outputs/bench/slam-<exp>-<device>.json. The
default log is the simulator (no data needed); real logs need their stream cache or raw files.

``--released``: in each repeat, the released C++ (eval/reference/gmapping.py's build, one core, the ROS
wrapper's settings, seed 0) runs on the same log right after ours, so that the ratio of the two is
measured side by side on a machine whose speed drifts from hour to hour.

``--match-at N``: the hill climb alone, at the first processed scan after scan N, in each way RBPF.match has
on the device (GPU: blocks, threads, rounds; CPU: threads, rounds), alternating, with an md5 of each way's
poses (they are the same bits).
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from eval.bench.timing import record_path
from irmcl_warp.services.outputs import write_json
from irmcl_warp.config import compose_config
from irmcl_warp.services.data import load_stream
from irmcl_warp.slam.stage import start_filter
from irmcl_warp.kernels import pick_device


def new_filter(exp: str, particles: int, device: str, overrides=()):
    """(filter, log, odometry) of ``exp`` with ``particles`` particles on ``device``, started at its first scan."""
    cfg = compose_config([f"+exp={exp}", f"device={device}", f"slam.num_particles={particles}", *overrides])
    log = load_stream(cfg)
    rbpf, odom = start_filter(cfg, log, device)
    return rbpf, log, odom


def run_one(exp: str, particles: int, device: str, scans: int | None, overrides=()) -> dict:
    rbpf, log, odom = new_filter(exp, particles, device, overrides)
    n = len(log) if scans is None else min(int(scans), len(log))
    t0 = time.perf_counter()
    processed = sum(rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k])).processed for k in range(1, n))
    wall = time.perf_counter() - t0
    return {
        "exp": exp,
        "particles": particles,
        "device": rbpf.device,
        "scans": n,
        "processed_scans": processed,
        "wall_s": wall,
        "ms_per_processed_scan": {k: 1e3 * v / max(processed, 1) for k, v in rbpf.timing.items()},
    }


def repeat_runs(runs: list[dict]) -> dict:
    """The run of median wall time among repeats of the same run, with every repeat's wall time beside it."""
    walls = sorted(r["wall_s"] for r in runs)
    median = next(r for r in runs if r["wall_s"] == walls[(len(walls) - 1) // 2])
    return {
        **median,
        "wall_s_all": [r["wall_s"] for r in runs],
        "wall_s_min": walls[0],
        "wall_s_max": walls[-1],
        "repeats": len(runs),
    }


def run_released(exp: str, particles: int, scans: int | None) -> float:
    """Wall time (s) of the released GMapping on the log (its first ``scans`` scans), seed 0, in a scratch
    folder (eval/reference/gmapping.py's driver and settings)."""
    import tempfile

    from eval.reference import gmapping as ref

    if not ref.BINARY.is_file():
        raise FileNotFoundError(
            f"{ref.BINARY}: --released needs the released code: bash eval/reference/build_gmapping.sh "
            "<openslam_gmapping clone>"
        )
    cfg = compose_config([f"+exp={exp}"])
    log = load_stream(cfg)
    if scans is not None:
        log = log.subset(slice(0, min(int(scans), len(log))))
    params = ref.wrapper_params(cfg, log, [f"particles={particles}"])
    with tempfile.TemporaryDirectory() as tmp:
        scans_file = Path(tmp) / "scans.txt"
        ref.export_scans(log, scans_file)
        return ref.run_binary(scans_file, Path(tmp), 0, params)


def run_match_bench(a, device: str) -> dict:
    """``--match-at N``: the filter run over the first N scans, then the hill climb of the next processed scan
    (its motion-model samples, on the maps of that moment) timed ``--match-repeats`` times in each way that
    runs on the device (RBPF.match ``how``), alternating; prints each way's median [min-max] ms and an md5 of
    its poses and scores (the ways give the same bits)."""
    import hashlib

    rbpf, log, odom = new_filter(a.exp, a.particles[0], device, a.override)
    k = 1
    while k < min(int(a.match_at), len(log) - 1):
        rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k]))
        k += 1
    caught, propose = [], rbpf.propose

    def catch(sampled, moved):  # the proposal's input: the climb's start at the next processed scan
        caught.append(sampled.copy())
        return propose(sampled, moved)

    rbpf.propose = catch
    while not caught and k < len(log):
        rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k]))
        k += 1
    if not caught:
        raise ValueError(f"--match-at {a.match_at}: no scan is processed after it in {a.exp}'s {len(log)} scans")
    ways = ["blocks", "threads", "rounds"] if device.startswith("cuda") else ["threads", "rounds"]
    times, digest, rounds = {w: [] for w in ways}, {}, {}
    for w in ways:  # once each first: compiles, and the poses' digest
        pose, best, rounds[w] = rbpf.match(caught[0], how=w)
        digest[w] = hashlib.md5(pose.tobytes() + best.tobytes()).hexdigest()
    for _ in range(int(a.match_repeats)):
        for w in ways:
            t0 = time.perf_counter()
            rbpf.match(caught[0], how=w)
            times[w].append(1e3 * (time.perf_counter() - t0))
    print(
        f"\nGMapping hill climb of {a.particles[0]} particles at scan {k - 1} of {a.exp} ({device}: its motion-model samples, on "
        f"the maps as the filter left them after that scan), {a.match_repeats} repeats per way, alternating"
    )
    print("| way (RBPF.match how=) | ms: median [min-max] | rounds | md5 of poses and scores |")
    print("|---|---|---|---|")
    for w in ways:
        t = times[w]
        print(f"| {w} | {np.median(t):.2f} [{min(t):.2f}-{max(t):.2f}] | {rounds[w]} | {digest[w]} |")
    out = record_path(a.out, "slam", device, "match", a.exp)
    out.parent.mkdir(parents=True, exist_ok=True)
    res = {"device": device, "argv": vars(a), "scan": k - 1, "ms": times, "rounds": rounds, "md5": digest}
    write_json(out, res)
    print(f"-> {out}")
    return res


def run_slam_bench(a) -> list[dict]:

    device = pick_device(a.device or "auto")
    if a.match_at is not None:
        return [run_match_bench(a, device)]
    rows = []
    for p in a.particles:
        runs, released = [], []
        for _ in range(a.repeats):
            runs.append(run_one(a.exp, p, device, a.scans, a.override))
            if a.released:
                released.append(run_released(a.exp, p, a.scans))
        row = repeat_runs(runs)
        if released:
            ratios = [r / o["wall_s"] for r, o in zip(released, runs)]
            row["released_wall_s_all"], row["released_over_ours_all"] = released, ratios
            row["released_wall_s"], row["released_over_ours"] = float(np.median(released)), float(np.median(ratios))
        rows.append(row)
    name = platform.processor() or "cpu"
    if device.startswith("cuda"):
        import torch

        name = torch.cuda.get_device_name()
    print(f"\nGMapping RBPF on {name} ({device}), {a.exp}, {rows[0]['scans']} scans")
    print(
        f"| particles | processed scans | wall (s): median of {a.repeats} [min-max] | matching | motion | "
        "weights + resampling | integration |  (ms per processed scan, of the median run)"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        t = r["ms_per_processed_scan"]
        print(
            f"| {r['particles']} | {r['processed_scans']} | {r['wall_s']:.1f} [{r['wall_s_min']:.1f}-{r['wall_s_max']:.1f}] | "
            f"{t['matching']:.1f} | {t['motion']:.1f} | {t['weights_resampling']:.1f} | {t['integration']:.1f} |"
        )
    for r in rows:
        if "released_wall_s" in r:
            print(
                f"released C++ ({r['particles']} particles, one core), each repeat right after ours: "
                f"{r['released_wall_s']:.1f} s median [{min(r['released_wall_s_all']):.1f}-"
                f"{max(r['released_wall_s_all']):.1f}]; released / ours {r['released_over_ours']:.2f} median "
                f"[{min(r['released_over_ours_all']):.2f}-{max(r['released_over_ours_all']):.2f}]"
            )
    out = record_path(a.out, "slam", device, a.exp)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(out, {"device": device, "device_name": name, "argv": vars(a), "rows": rows})
    print(f"-> {out}")
    return rows


def add_parser(sub) -> None:
    p = sub.add_parser("slam", help="wall time of GMapping's RBPF over a log, per part of a processed scan")
    p.add_argument("--exp", default="gmapping_sim")
    p.add_argument("--particles", type=int, nargs="+", default=[30])
    p.add_argument("--device", default=None)
    p.add_argument("--scans", type=int, default=None, help="only the first N scans")
    p.add_argument("--override", nargs="*", default=[], help="more Hydra overrides, e.g. sim.duration_s=60")
    p.add_argument("--repeats", type=int, default=5, help="runs per particle count; the table shows the median run")
    p.add_argument(
        "--released",
        action="store_true",
        help="time the released C++ on the same log after each repeat (eval/reference/build_gmapping.sh)",
    )
    p.add_argument(
        "--match-at",
        type=int,
        default=None,
        help="time the hill climb alone, in each way, at the first processed scan after scan N",
    )
    p.add_argument("--match-repeats", type=int, default=15, help="with --match-at: timings per way")
    p.add_argument("--out", default="outputs/bench")
