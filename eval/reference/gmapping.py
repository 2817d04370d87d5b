"""``python -m eval.reference.gmapping +exp=gmapping_fr079 [--seeds 0-9] [--keep]``: the released GMapping on
our logs, scored by our relations metric, so every released-code figure a table shows is a run anyone repeats.

The released code (OpenSLAM GMapping as ros-perception/openslam_gmapping packages it) is built outside the
project by ``bash eval/reference/build_gmapping.sh <clone>`` with our driver ``gmapping_replay.cpp``, which
replays a log the way the ROS wrapper (slam_gmapping) feeds it: the wrapper's defaults, laser poses from the
odometry and the base->laser extrinsic, ``maxRange`` = the scan's ``range_max`` - 0.01. This command writes
the log as the driver reads it (no-return beams as the no-return value, as the bag holds them), runs the
seeds (``seed`` k seeds drand48 with k + 1: 0 would leave it unseeded), and scores each path like our own
runs: a pose at every scan (the best particle's pose at the last processed scan plus the odometry since),
the relations on the laser's path. Runs go to ``outputs/<exp>/reference_gmapping/<N>p[-<settings>]-seed<k>-<digest>/``
(``irmcl_warp.runs.tool_dir``; metrics.json,
trajectory.tum, neff.txt); ``--keep`` merges them into ``results/slam/reference/<exp>.json``.
``--matcher``, ``--motion`` and ``--neff`` compare one part of ours with the released code's instead.

Settings left at the wrapper's defaults unless given with ``--set key=value`` (the driver's parameter names).
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import re
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from eval.results.queries import DERIVED_SETTINGS, TOOL, reference_variant, slam_variant
from irmcl_warp import runs
from irmcl_warp.config import compose_config
from irmcl_warp.geometry import compose
from irmcl_warp.io import read_bag, read_relations, resolve, write_tum
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.services.cli import guard
from irmcl_warp.services.data import load_stream
from irmcl_warp.services.metrics import relations_error
from irmcl_warp.services.outputs import write_json
from irmcl_warp.slam.rbpf import per_scan_poses
from irmcl_warp.slam.stage import filter_frame, relation_stamps
from irmcl_warp.types import match_stamps

REPO = Path(__file__).resolve().parents[2]
BINARY = REPO / "outputs" / "reference" / "gmapping" / "gmapping_replay"


def scan_range_max(cfg) -> float:
    """The LaserScan's range_max of the log's bag (the wrapper's maxRange is it - 0.01): the data path when it
    is a bag, else the bag that gives the extrinsic (the derived CARMEN logs carry no range_max)."""
    bag = cfg.data.path if cfg.data.format == "bag" else cfg.data.get("laser_frame_path")
    if not bag:
        raise ValueError(f"data={cfg.data.name}: no bag to take range_max from; give --set maxRange=...")
    return read_bag(resolve(bag)).info.range_max_m


def export_scans(log, path: Path) -> None:
    """One line per scan: the laser's odometry pose and the ranges, no-return beams as the no-return value."""
    laser = compose(log.odom, log.T_base_laser)
    ranges = np.where(np.isfinite(log.ranges_m), log.ranges_m, log.info.no_return_m)
    lines = [
        f"{t:.6f} {x:.6f} {y:.6f} {a:.6f} {len(r)} " + " ".join(f"{v:.3f}" for v in r)
        for t, (x, y, a), r in zip(log.stamps, laser, ranges)
    ]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def wrapper_params(cfg, log, chosen=()) -> dict:
    """The driver's parameters: ``chosen`` ("key=value" strings, the wrapper's defaults elsewhere), maxRange
    from the bag's range_max as the wrapper takes it (unless chosen) and the log's beam increment."""
    params = dict(kv.split("=", 1) for kv in chosen)
    params.setdefault("maxRange", f"{scan_range_max(cfg) - 0.01:.4f}")
    params["angleIncrement"] = f"{log.info.angle_increment_rad:.9f}"
    return params


def run_binary(scans_file: Path, out: Path, seed: int, params: dict) -> float:
    """Runs the driver on ``scans_file`` (path.txt and neff.txt into ``out``), drand48 seeded with seed + 1
    (0 would leave it unseeded); returns its wall time (s)."""
    args = [str(BINARY), str(scans_file), str(out / "path.txt"), str(out / "neff.txt"), f"seed={seed + 1}"]
    t0 = time.perf_counter()
    ran = subprocess.run(args + [f"{k}={v}" for k, v in params.items()], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if ran.returncode != 0:
        raise RuntimeError(f"gmapping_replay seed {seed} failed ({ran.returncode}): {ran.stderr[-1000:]}")
    return wall


def data_tag(overrides) -> str:
    """A folder-name part for Hydra overrides of the log's data config: data.laser_offset=[0,0,0] ->
    laser_offset0_0_0."""
    parts = [o.removeprefix("data.").split("=", 1) for o in overrides]
    return "-".join(key + re.sub(r"[^A-Za-z0-9.]+", "_", value).strip("_") for key, value in parts)


def run_seed(cfg, log, scans_file: Path, seed: int, params: dict, out_root: Path, data_overrides=()) -> dict:
    n = int(params.get("particles", 30))
    chosen = "-".join(
        [
            *(f"{k}{v}" for k, v in sorted(params.items()) if k not in DERIVED_SETTINGS + ("particles",)),
            *([data_tag(data_overrides)] if data_overrides else []),
        ]
    )
    name = f"{n}p{'-' + chosen if chosen else ''}-seed{seed}"
    out = runs.tool_dir(cfg.exp, TOOL, name, {"settings": params, "data": list(data_overrides), "seed": seed}, out_root)
    out.mkdir(parents=True, exist_ok=True)
    done = out / "metrics.json"
    if done.is_file():  # a finished run of the same settings: kept, not run again (an interrupted sweep resumes)
        m = json.loads(done.read_text())
        if (
            m.get("settings") == {k: float(v) for k, v in params.items()}
            and m.get("drand48_seed") == seed + 1
            and m.get("data_overrides", []) == list(data_overrides)
        ):
            return m
    wall = run_binary(scans_file, out, seed, params)
    path = np.loadtxt(out / "path.txt", ndmin=2)
    processed = match_stamps(log.stamps, path[:, 0], 1e-5)
    if (processed < 0).any():
        raise RuntimeError(f"{out / 'path.txt'}: {int((processed < 0).sum())} stamps match no scan of the log")
    laser_odom = compose(log.odom, log.T_base_laser)
    every = per_scan_poses(np.arange(len(log)), processed, path[:, 1:4], laser_odom)
    write_tum(out / "trajectory.tum", log.stamps, every)
    rel = read_relations(resolve(cfg.data.relations_path))
    stamps = relation_stamps(cfg, log)
    neff = np.loadtxt(out / "neff.txt", ndmin=2)
    metrics = {
        "dataset": cfg.data.name,
        "implementation": "released GMapping (openslam_gmapping "
        f"{(BINARY.parent / 'COMMIT').read_text().split()[0]}) via eval/reference/gmapping_replay.cpp",
        "particles": n,
        "seed": seed,
        "drand48_seed": seed + 1,
        "scans": len(log),
        "processed_scans": int(len(processed)),
        "wall_time_s": wall,
        "resamplings_upper_bound": int(np.sum(neff[:, 1] < 0.5 * n)) if len(neff) else 0,
        "settings": {k: float(v) for k, v in params.items()},
        "data_overrides": list(data_overrides),
        "relations_frame": {"frame": "laser", "T_base_laser": [float(v) for v in log.T_base_laser]},
        "relations": relations_error(stamps, every, rel),
    }
    metrics["run"] = name
    write_json(out / "metrics.json", metrics)
    return metrics


GFS = BINARY.parent / "gfs_nogui"
GFS2LOG = BINARY.parent / "gfs2log"


def read_gfs_path(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps [K], poses [K, 3]) of the best particle from gfs2log's CARMEN log: its ODOM lines, one per
    reading, ``ODOM x y theta tv rv accel stamp host logger_stamp`` (the corrected pose at each reading's
    stamp; the line stamped 0 is the start it prints before the first reading, dropped). A stamp given twice
    keeps its last pose; a line that is not that is an error naming the file and the line."""
    poses = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.startswith("ODOM"):
            continue
        f = line.split()
        try:
            x, y, a, stamp = float(f[1]), float(f[2]), float(f[3]), float(f[7])
        except (IndexError, ValueError):
            raise ValueError(
                f"{path}, line {n}: expected 'ODOM x y theta tv rv accel stamp host logger_stamp'"
            ) from None
        if stamp > 0:
            poses[round(stamp, 6)] = (x, y, a)
    if not poses:
        raise ValueError(f"{path}: no ODOM line with a stamp: did gfs_nogui process the log?")
    stamps = np.array(sorted(poses))
    return stamps, np.array([poses[t] for t in stamps])


def gfs_log(cfg, out_root: Path) -> Path:
    """The data config's CARMEN log as plain text (gfs_nogui reads no gzip), written once for all seeds."""
    if cfg.data.format != "carmen":
        raise ValueError(f"data={cfg.data.name}: gfs_nogui reads CARMEN logs; this one is {cfg.data.format}")
    src, plain = resolve(cfg.data.path), runs.cache_dir(cfg, f"{TOOL}-inputs", out_root) / "gfs-log.clf"
    if str(src).endswith(".gz"):
        with gzip.open(src) as f:
            atomic_write_bytes(plain, f.read())
    else:
        atomic_write_bytes(plain, src.read_bytes())
    return plain


GFS_PARTICLES = 30  # gfs_nogui's default


def run_gfs_seed(cfg, log, clf: Path, seed: int, out_root: Path) -> dict:
    """The released code's own CARMEN-log tool, gfs_nogui, on ``clf`` (gfs_log) with its defaults, seeded with
    seed + 1; the best particle's path through gfs2log, scored like our runs. Its defaults differ from the ROS
    wrapper's (rotational noise srt = stt = 0.1 instead of 0.2, a scan also processed 5 s after the last one,
    maxrange 80 m), and its reader gives FLASER beams its own angles (irmcl_warp.io.carmen.gfs_flaser_angles)
    and puts the laser at the FLASER pose."""
    for exe in (GFS, GFS2LOG):
        if not exe.is_file():
            raise FileNotFoundError(
                f"{exe}: build it first: bash eval/reference/build_gmapping.sh <openslam_gmapping clone>"
            )
    name = f"gfs-{GFS_PARTICLES}p-seed{seed}"
    out = runs.tool_dir(cfg.exp, TOOL, name, {"tool": "gfs_nogui", "seed": seed}, out_root)
    out.mkdir(parents=True, exist_ok=True)  # gfs_nogui writes rawpath.dat and w-*.dat into its working folder
    done = out / "metrics.json"
    if done.is_file():
        m = json.loads(done.read_text())
        if m.get("tool") == "gfs_nogui" and m.get("randseed") == seed + 1:
            return m
    t0 = time.perf_counter()
    ran = subprocess.run(
        [str(GFS), "-filename", str(clf.resolve()), "-outfilename", "run.gfs", "-randseed", str(seed + 1)],
        cwd=out,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t0
    if ran.returncode != 0 or "DONE!" not in ran.stdout:
        raise RuntimeError(f"gfs_nogui seed {seed} failed ({ran.returncode}): {ran.stderr[-1000:]}")
    subprocess.run([str(GFS2LOG), "run.gfs", "best.log"], cwd=out, capture_output=True, check=True)
    stamps, poses = read_gfs_path(out / "best.log")
    idx = match_stamps(log.stamps, stamps, 1e-5)
    if (idx < 0).any():
        raise RuntimeError(f"{out / 'best.log'}: {int((idx < 0).sum())} stamps match no scan of {cfg.data.path}")
    if len(np.unique(idx)) != len(log):
        raise RuntimeError(f"{out / 'best.log'}: poses at {len(np.unique(idx))} of the log's {len(log)} scans")
    every = np.empty((len(log), 3))
    every[idx] = poses  # the laser's path (the FLASER pose, laser at the robot's centre as gfs reads it)
    write_tum(out / "trajectory.tum", log.stamps, every)
    neff = [float(line.split()[1]) for line in (out / "best.log").read_text().splitlines() if line.startswith("NEFF")]
    rel = read_relations(resolve(cfg.data.relations_path))
    metrics = {
        "dataset": cfg.data.name,
        "implementation": "released GMapping (openslam_gmapping "
        f"{(BINARY.parent / 'COMMIT').read_text().split()[0]}), its gfs_nogui on the CARMEN log",
        "tool": "gfs_nogui",
        "particles": GFS_PARTICLES,
        "seed": seed,
        "randseed": seed + 1,
        "scans": len(log),
        "processed_scans": len(neff),
        "wall_time_s": wall,
        "host": f"{os.cpu_count()}-core CPU",
        "resamplings_upper_bound": int(sum(v < 0.5 * GFS_PARTICLES for v in neff)),
        "settings": {},
        "data_overrides": [],
        "relations_frame": {"frame": "laser", "T_base_laser": [0.0, 0.0, 0.0]},
        "relations": relations_error(relation_stamps(cfg, log), every, rel),
    }
    metrics["run"] = name
    for junk in [out / "run.gfs", out / "rawpath.dat", *out.glob("w-*.dat")]:
        junk.unlink(missing_ok=True)  # 10-20 MB a run; best.log keeps the path
    write_json(done, metrics)
    return metrics


MOTION = BINARY.parent / "gmapping_motion"
# odometry steps (old pose, new pose) of the kinds a log holds: straight, turning, sideways slip, turning on
# the spot; the particle starts elsewhere with another heading
MOTION_CASES = {
    "straight": ((1.0, 0.0, 0.3), (1.4, 0.12, 0.3)),
    "turning": ((1.0, 0.0, 0.3), (1.25, 0.1, 0.7)),
    "sideways": ((0.0, 0.0, 0.0), (0.02, 0.15, 0.05)),
    "on the spot": ((2.0, 1.0, -2.9), (2.0, 1.0, 2.9)),
}


def motion_check(samples: int = 200_000, noise=(0.1, 0.2, 0.1, 0.2)) -> dict:
    """Our GMapping motion model (kernels.slam motion_kernel) against the released code's drawFromMotion on
    the same steps: mean and standard deviation of x, y, theta over ``samples`` draws each. Agreement means
    mean differences within 5 standard errors and deviations within 2 %."""
    import warp as wp

    from irmcl_warp.geometry import relative, wrap_angle
    from irmcl_warp.kernels import SLAM

    if not MOTION.is_file():
        raise FileNotFoundError(f"{MOTION}: build it first: bash eval/reference/build_gmapping.sh <clone>")
    start = np.array([3.0, -1.0, 1.2])
    ours_model = SLAM.build("motion", srr=noise[0], srt=noise[1], str_=noise[2], stt=noise[3], device="cpu")
    report = {}
    for name, (old, new) in MOTION_CASES.items():
        args = [str(MOTION), *map(str, noise), *map(str, start), *map(str, new), *map(str, old), str(samples), "7"]
        released = np.loadtxt(subprocess.run(args, capture_output=True, text=True, check=True).stdout.splitlines())
        poses = wp.array(np.tile(start, (samples, 1)).astype(np.float32), dtype=wp.vec3, device="cpu")
        ours_model(poses, relative(np.array(old)[None], np.array(new)[None])[0], seed=11)
        ours = poses.numpy().astype(np.float64)
        for a in (released, ours):  # headings around the mean, so a wrap at pi does not split the cloud
            a[:, 2] = wrap_angle(a[:, 2] - start[2])
        m_r, m_o, s_r, s_o = released.mean(0), ours.mean(0), released.std(0), ours.std(0)
        z = np.abs(m_r - m_o) / np.sqrt((s_r**2 + s_o**2) / samples)
        ratio = s_o / s_r
        report[name] = {
            "released_mean": m_r.tolist(),
            "ours_mean": m_o.tolist(),
            "released_std": s_r.tolist(),
            "ours_std": s_o.tolist(),
            "mean_z": z.tolist(),
            "std_ratio": ratio.tolist(),
            "agree": bool((z < 5).all() and (np.abs(ratio - 1) < 0.02).all()),
        }
    return {"samples": samples, "noise_srr_srt_str_stt": list(noise), "start": start.tolist(), "cases": report}


MATCHER = BINARY.parent / "gmapping_matcher"


def matcher_check(
    log,
    registered: int = 20,
    queries: int = 10,
    usable_m: float = 40.0,
    delta: float = 0.05,
    seed: int = 0,
    sigma=0.05,
    kernel=1,
    lstep=0.05,
    astep=0.05,
    iterations=5,
    lsigma=0.075,
) -> dict:
    """Our matcher model (the numpy twins of kernels/slam/: end-point maps, score, likelihood, hill climbing)
    against the released ScanMatcher on the same scans: ``registered`` scans of the log at their ground-truth
    poses make one map on each side (end points only, as the wrapper runs it); ``queries`` later scans are
    scored at their true pose and at perturbed ones, and climbed from a perturbed pose. The cells are aligned:
    our corner origin is the released map's centre minus (half its size + half a cell)."""
    from irmcl_warp.reference.slam import hill_climb, integrate, score

    if not MATCHER.is_file():
        raise FileNotFoundError(
            f"{MATCHER}: build it first: bash eval/reference/build_gmapping.sh <openslam_gmapping clone>"
        )
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: the matcher check poses its scans by ground truth, and this log has none")
    posed = np.flatnonzero(np.all(np.isfinite(log.ground_truth), axis=1))
    if len(posed) < registered + queries:
        raise ValueError(f"{log.source}: {len(posed)} scans with ground truth, the check needs {registered + queries}")
    reg, qry = posed[:registered], posed[registered : registered + queries]
    rng = np.random.default_rng(seed)
    angles, T = log.info.angles_rad, np.asarray(log.T_base_laser, float)
    # the wrapper's map, -100..100 m: centred on the world's origin. (The released free-cell test looks up the
    # cell at pr + world2map(a small vector); with the map centred on the origin that cell lies beyond the map
    # and reads unknown, so the test passes, as ours with free_check=False. Centred elsewhere it lands inside.)
    lo, hi = np.array([-100.0, -100.0]), np.array([100.0, 100.0])
    if np.abs(log.ground_truth[reg, :2]).max() + usable_m > 100:
        raise ValueError(f"{log.source}: the scans reach beyond the wrapper's -100..100 m map")
    fed = lambda r: " ".join(f"{v:.6f}" for v in np.where(np.isfinite(r), r, 1e4))  # noqa: E731 (no return: skipped)
    pose_txt = lambda p: " ".join(f"{v:.9f}" for v in p)  # noqa: E731
    perturbed = [log.ground_truth[k] + rng.normal(0, 1, 3) * [0.05, 0.05, np.radians(2)] for k in qry]
    lines = [
        f"MAP {lo[0]} {lo[1]} {hi[0]} {hi[1]} {delta}",
        f"LASER {len(angles)} {pose_txt(T)} " + " ".join(f"{a:.12f}" for a in angles),
        f"PARAMS {usable_m} {usable_m} {sigma} {kernel} {lstep} {astep} {iterations} {lsigma} 0",
    ]
    lines += [f"R {pose_txt(log.ground_truth[k])} {fed(log.ranges_m[k])}" for k in reg]
    scored = [(k, p) for k, off in zip(qry, perturbed) for p in (log.ground_truth[k], off)]  # true, then perturbed
    lines += [f"S {pose_txt(p)} {fed(log.ranges_m[k])}" for k, p in scored]
    lines += [f"O {pose_txt(perturbed[j])} {fed(log.ranges_m[k])}" for j, k in enumerate(qry)]
    out = subprocess.run(
        [str(MATCHER)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True
    ).stdout
    rows = [line.split() for line in out.splitlines()]
    cx, cy, _, sx2, sy2 = (float(v) for v in rows[0][1:6])
    origin = (cx - (sx2 + 0.5) * delta, cy - (sy2 + 0.5) * delta)
    H, W = int(2 * sy2), int(2 * sx2)
    maps = {k: np.zeros((H, W)) for k in ("visits", "hits", "sx", "sy")}
    for k in reg:
        integrate(maps, log.ground_truth[k], T, log.ranges_m[k], angles, usable_m, origin, delta, free_space=False)

    def ours_s(p, k):
        return score(
            maps, p, T, log.ranges_m[k], angles, usable_m, origin, delta, kernel, 0.1, sigma, lsigma, free_check=False
        )

    released_s = [tuple(map(float, r[1:])) for r in rows if r[0] == "S"]
    released_o = [tuple(map(float, r[1:])) for r in rows if r[0] == "O"]
    ours = [ours_s(p, k) for k, p in scored]
    climbs = []
    for j, k in enumerate(qry):
        evaluate = lambda c, k=k: np.array([[ours_s(p, k)[0] for p in row] for row in c])  # noqa: E731
        pose, best, _ = hill_climb(evaluate, perturbed[j][None], lstep, astep, iterations)
        climbs.append(
            {
                "start": perturbed[j].tolist(),
                "released": list(released_o[j]),
                "ours": [*pose[0].tolist(), float(best[0])],
            }
        )
    s_err = [abs(a[0] - b[0]) / max(abs(b[0]), 1e-9) for a, b in zip(ours, released_s)]
    l_err = [abs(a[1] - b[1]) / max(abs(b[1]), 1e-9) for a, b in zip(ours, released_s)]
    c_err = [float(np.hypot(c["ours"][0] - c["released"][0], c["ours"][1] - c["released"][1])) for c in climbs]
    return {
        "log": str(log.source),
        "registered_scans": [int(k) for k in reg],
        "query_scans": [int(k) for k in qry],
        "usable_m": usable_m,
        "delta_m": delta,
        "settings": {
            "sigma": sigma,
            "kernel": kernel,
            "lstep": lstep,
            "astep": astep,
            "iterations": iterations,
            "lsigma": lsigma,
        },
        "scores": [{"ours": list(a), "released": list(b)} for a, b in zip(ours, released_s)],
        "score_rel_diff_max": float(max(s_err)),
        "loglik_rel_diff_max": float(max(l_err)),
        "climbs": climbs,
        "climb_pose_diff_m_max": float(max(c_err)),
        "climb_score_rel_diff_max": float(
            max(abs(c["ours"][3] - c["released"][3]) / max(c["released"][3], 1e-9) for c in climbs)
        ),
    }


def neff_check(exp: str, data_overrides=(), outputs: Path = REPO / "outputs") -> dict:
    """The resampling decisions and N_eff along whole runs, ours (``neff.csv`` of our finished ``gmapping_code``
    runs with 30 particles of ``exp``, at its settings but for the beam geometry ``data_overrides`` set) against
    the released code's (``neff.txt`` of its wrapper replays with 30 particles and the same overrides), both
    under ``outputs``. The released driver logs N_eff after ``processScan``, which normalises again after
    resampling: a scan it resampled reads exactly N (30), so those are its resamplings (the first scan, which
    registers, also reads N). The runs are stochastic and drift apart, so the comparison is of distributions:
    resamplings per run (Mann-Whitney) and N_eff on the scans that were not resampled (quartiles, KS; the
    scans of a run are correlated, so its p-value is an upper bound on the evidence)."""
    from scipy.stats import ks_2samp, mannwhitneyu

    base = compose_config([f"+exp={exp}"]).data
    chosen = compose_config([f"+exp={exp}", *data_overrides]).data
    variant = {f"data.{k}": chosen[k] for k in ("fov_rad", "angle_min_rad", "laser_offset") if chosen[k] != base[k]}
    variant = {k: list(v) if hasattr(v, "__len__") else v for k, v in variant.items()}
    ours = [
        r
        for r in runs.find(
            "slam", exp, outputs, slam__proposal="gmapping_code", slam__resample="selective", slam__num_particles=30
        )
        if slam_variant(r) == variant
    ]
    released = [
        f
        for f in runs.tool_runs(TOOL, exp, outputs)
        if (m := json.loads((f / "metrics.json").read_text())).get("particles") == 30
        and m.get("tool") != "gfs_nogui"
        and list(m.get("data_overrides", [])) == list(data_overrides)
        and reference_variant({**m, "data_overrides": []}) == ""
    ]
    rel_runs, our_runs = [f / "neff.txt" for f in released], [r.path / "neff.csv" for r in ours]
    if not rel_runs or not our_runs:
        raise FileNotFoundError(
            f"{outputs}/{exp}: need runs of both (the released code's: {len(rel_runs)}, ours "
            f"with slam.proposal=gmapping_code and 30 particles: {len(our_runs)})"
        )
    rel_counts, rel_neff, our_counts, our_neff = [], [], [], []
    for f in rel_runs:
        a = np.loadtxt(f, ndmin=2)[:, 1]
        n = float(np.max(a))  # the particle count: what a fresh or resampled set reads
        resampled = np.abs(a[1:] - n) < 1e-4
        rel_counts.append(int(resampled.sum()))
        rel_neff.append(a[1:][~resampled])
    for f in our_runs:
        o = np.genfromtxt(f, delimiter=",", names=True)
        our_counts.append(int(o["resampled"].sum()))
        our_neff.append(o["neff"][o["resampled"] == 0])
    r, o = np.concatenate(rel_neff), np.concatenate(our_neff)
    return {
        "exp": exp,
        "released_runs": [f.parent.name for f in rel_runs],
        "our_runs": [r.label for r in ours],
        "data_overrides": list(data_overrides),
        "resamplings_released": rel_counts,
        "resamplings_ours": our_counts,
        "resamplings_median": [float(np.median(rel_counts)), float(np.median(our_counts))],
        "resamplings_mannwhitney_p": float(mannwhitneyu(rel_counts, our_counts).pvalue),
        "neff_quartiles_released": np.quantile(r, [0.25, 0.5, 0.75]).tolist(),
        "neff_quartiles_ours": np.quantile(o, [0.25, 0.5, 0.75]).tolist(),
        "neff_ks_p": float(ks_2samp(r, o).pvalue),
        "scans_released": int(len(r)),
        "scans_ours": int(len(o)),
    }


def seeds_of(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


TRACE_NOISE_FREE = ("particles=1", "srr=0", "srt=0", "str=0", "stt=0")


def trace_check(
    exp: str,
    delta: float | None = None,
    margin_m: float = 10.0,
    scans: int | None = None,
    data_overrides=(),
    tol_m: float = 0.01,
    tol_deg: float = 0.5,
    frame: str = "base",
) -> dict:
    """The whole filter, differentially: one particle, no motion noise, so that both sides are deterministic
    (scan matching from the odometry's prediction, then the scan added to the map), on the same log and the
    same inputs (the wrapper's beam layout, usable range = maxRange, our cells aligned on the released map's:
    boundaries at (k + 1/2) delta). The poses at the processed scans agree until one side's map or matcher
    differs; the first scan where they part by more than ``tol_m`` / ``tol_deg`` is where to look.
    Ours runs on the CPU, its first map ``margin_m`` around the first pose (both sides' maps grow to fit)."""
    from irmcl_warp.geometry import wrap_angle
    from irmcl_warp.slam.rbpf import RBPF

    cfg = compose_config(
        [
            f"+exp={exp}",
            *data_overrides,
            "slam.num_particles=1",
            "slam.srr=0",
            "slam.srt=0",
            "slam.str=0",
            "slam.stt=0",
            "slam.proposal=gmapping_code",
            f"slam.frame={frame}",
            *([f"slam.resolution_m={delta}"] if delta else []),
        ]
    )
    log = load_stream(cfg)
    if scans:
        log = log.subset(np.arange(min(scans, len(log))))
    delta = float(cfg.slam.resolution_m)
    params = wrapper_params(cfg, log, [*TRACE_NOISE_FREE, f"delta={delta}"])
    out = runs.tool_dir(
        exp,
        "trace_gmapping",
        f"{delta:g}m",
        {"data": list(data_overrides), "frame": frame, "scans": scans},
        REPO / "outputs",
    )
    out.mkdir(parents=True, exist_ok=True)
    export_scans(log, out / "scans.txt")
    wall_released = run_binary(out / "scans.txt", out, 0, params)
    released = np.loadtxt(out / "path.txt", ndmin=2)
    n, inc = log.info.num_beams, float(params["angleIncrement"])
    angles = (-0.5 * n + np.arange(n)) * inc  # the RangeSensor the wrapper builds: from -n inc / 2
    # our first map around the first pose, its cells on the released lattice; it grows by whole cells
    odom, T = filter_frame(cfg, log)  # slam.frame: the base's poses (ours by default) or the laser's
    origin = (np.floor((odom[0, :2] - margin_m) / delta - 0.5) + 0.5) * delta
    n = int(np.ceil(2 * margin_m / delta))
    rbpf = RBPF(cfg.slam, (n, n), tuple(origin), T, angles, float(params["maxRange"]), "cpu")
    t0 = time.perf_counter()
    rbpf.start(odom[0], log.ranges_m[0], float(log.stamps[0]))
    for k in range(1, len(log)):
        rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k]))
    wall_ours = time.perf_counter() - t0
    ours_idx, ours = rbpf.trajectory(0)
    ours = compose(ours, T)  # the released code's poses are the laser's
    rel_idx = match_stamps(log.stamps, released[:, 0], 1e-5)
    one_step = one_step_check(rbpf, log, odom, T, rel_idx, released[:, 1:4], tol_m, tol_deg)
    common = np.intersect1d(ours_idx, rel_idx)
    a = ours[np.searchsorted(ours_idx, common)]
    b = released[np.searchsorted(rel_idx, common), 1:4]
    d_xy = np.hypot(*(a[:, :2] - b[:, :2]).T)
    d_deg = np.degrees(np.abs(wrap_angle(a[:, 2] - b[:, 2])))
    parted = np.flatnonzero((d_xy > tol_m) | (d_deg > tol_deg))
    first = int(parted[0]) if len(parted) else None
    report = {
        "log": str(log.source),
        "exp": exp,
        "frame": frame,
        "delta_m": delta,
        "scans": len(log),
        "settings": params,
        "data_overrides": list(data_overrides),
        "margin_m": margin_m,
        "origin": origin.tolist(),
        "processed_ours": int(len(ours_idx)),
        "processed_released": int(len(rel_idx)),
        "processed_both": int(len(common)),
        "processed_only_ours": np.setdiff1d(ours_idx, rel_idx)[:20].tolist(),
        "processed_only_released": np.setdiff1d(rel_idx, ours_idx)[:20].tolist(),
        "tolerance": {"m": tol_m, "deg": tol_deg},
        "first_parted": None
        if first is None
        else {"processed": first, "scan": int(common[first]), "ours": a[first].tolist(), "released": b[first].tolist()},
        "pose_diff_m": {"median": float(np.median(d_xy)), "max": float(d_xy.max()), "last": float(d_xy[-1])},
        "yaw_diff_deg": {"median": float(np.median(d_deg)), "max": float(d_deg.max()), "last": float(d_deg[-1])},
        "wall_s": {"ours_cpu": wall_ours, "released": wall_released},
        "one_step": one_step,
        "per_processed": {
            "scan": common.tolist(),
            "d_m": np.round(d_xy, 6).tolist(),
            "d_deg": np.round(d_deg, 5).tolist(),
        },
    }
    write_json(out / "trace.json", report)
    return report


def one_step_check(
    rbpf, log, odom: np.ndarray, T: np.ndarray, idx: np.ndarray, released: np.ndarray, tol_m: float, tol_deg: float
) -> dict:
    """Our matcher led by the released run (one particle, no noise): at each processed scan, our map holds
    the scans added at the released poses so far, and we climb from the released previous pose moved by the
    odometry, as the released code did. Our pose against its pose, scan by scan: what a free-running
    comparison cannot show once the two paths have parted by a rounding."""
    from irmcl_warp.geometry import inverse, relative, wrap_angle

    T = np.asarray(T, float)
    base = compose(released, inverse(T)[None])
    rbpf.maps.cells.zero_()
    rbpf.start(base[0], log.ranges_m[idx[0]])
    d_m, d_deg, start_m = [], [], []
    for j in range(1, len(idx)):
        predicted = compose(base[j - 1][None], relative(odom[idx[j - 1]][None], odom[idx[j]][None]))
        rbpf._set_ranges(log.ranges_m[idx[j]])
        matched, _, _ = rbpf.match(predicted)
        ours = compose(matched, T[None])[0]
        d_m.append(float(np.hypot(*(ours[:2] - released[j, :2]))))
        d_deg.append(float(np.degrees(abs(wrap_angle(ours[2] - released[j, 2])))))
        start_m.append(float(np.hypot(*(predicted[0, :2] - base[j, :2]))))
        rbpf.poses.assign(wp_vec3(base[j][None]))
        rbpf._add_scan(base[j][None])
    d_m, d_deg = np.array(d_m), np.array(d_deg)
    off = (d_m > tol_m) | (d_deg > tol_deg)
    return {
        "steps": int(len(d_m)),
        "parted": int(off.sum()),
        "parted_scans": idx[1:][off][:50].tolist(),
        "d_m_quantiles": np.quantile(d_m, [0.5, 0.9, 0.99, 1.0]).tolist(),
        "d_deg_quantiles": np.quantile(d_deg, [0.5, 0.9, 0.99, 1.0]).tolist(),
        "exact": int(((d_m < 1e-4) & (d_deg < 1e-3)).sum()),
        "correction_m_median": float(np.median(start_m)),
        "per_step": {"scan": idx[1:].tolist(), "d_m": np.round(d_m, 6).tolist(), "d_deg": np.round(d_deg, 5).tolist()},
    }


def wp_vec3(a: np.ndarray):
    import warp as wp

    return wp.array(np.asarray(a, np.float32), dtype=wp.vec3, device="cpu")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.reference.gmapping")
    ap.add_argument("exp", help="+exp=<name>, e.g. +exp=gmapping_fr079")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--set", action="append", default=[], help="driver parameter key=value (e.g. particles=60)")
    ap.add_argument(
        "--data",
        action="append",
        default=[],
        help="Hydra override of the log's data config, e.g. "
        "data.laser_offset=[0,0,0] (the laser at the base: the CARMEN log's FLASER pose); in the run's name",
    )
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--keep", action="store_true", help="merge the runs into results/slam/reference/<exp>.json")
    ap.add_argument("--keep-only", action="store_true", help="run nothing: merge the finished runs in outputs/")
    ap.add_argument(
        "--matcher",
        action="store_true",
        help="run nothing else: our scan matcher's score, likelihood "
        "and hill climbing against the released one's on the log's scans (results/checks/gmapping_matcher_<exp>.json)",
    )
    ap.add_argument(
        "--motion",
        action="store_true",
        help="run nothing else: our motion model against the "
        "released one's samples (results/checks/gmapping_motion.json)",
    )
    ap.add_argument(
        "--neff",
        action="store_true",
        help="run nothing else: resamplings and N_eff of our finished gmapping_code runs (30 particles; the "
        "beam geometry of --data) against the released code's (results/checks/gmapping_neff_<exp>.json)",
    )
    ap.add_argument(
        "--trace",
        action="store_true",
        help="run nothing else: one particle without motion noise on "
        "both sides, the poses at every processed scan compared (results/checks/gmapping_trace_<exp>.json)",
    )
    ap.add_argument("--scans", type=int, help="--trace: only the first SCANS scans of the log")
    ap.add_argument("--delta", type=float, help="--trace: the cell size (default: the experiment's slam.resolution_m)")
    ap.add_argument(
        "--gfs",
        action="store_true",
        help="run the released code's own CARMEN-log tool (gfs_nogui, its "
        "defaults) on the data config's CARMEN log instead of our replay of the ROS wrapper",
    )
    ap.add_argument("--frame", default="base", help="--trace: our slam.frame (base, or laser as the released code)")
    a = ap.parse_args(argv)
    if a.trace:
        exp = a.exp.removeprefix("+exp=")
        r = trace_check(exp, a.delta, scans=a.scans, data_overrides=a.data, frame=a.frame)
        f = r["first_parted"]
        print(
            f"{exp}: {r['processed_both']} scans processed by both (ours {r['processed_ours']}, released "
            f"{r['processed_released']}); pose difference median {r['pose_diff_m']['median']:.4f} m, max "
            f"{r['pose_diff_m']['max']:.3f} m, yaw max {r['yaw_diff_deg']['max']:.2f} deg; "
            + (f"first parted at processed scan {f['processed']} (log scan {f['scan']})" if f else "never parted")
        )
        o = r["one_step"]
        print(
            f"led by the released poses: {o['parted']} of {o['steps']} steps part (> {r['tolerance']['m']} m or "
            f"{r['tolerance']['deg']} deg), {o['exact']} agree to 0.1 mm; pose difference quantiles (50/90/99/100 %) "
            f"{np.round(o['d_m_quantiles'], 4).tolist()} m, {np.round(o['d_deg_quantiles'], 3).tolist()} deg"
        )
        name = (
            f"gmapping_trace_{exp}{'-' + data_tag(a.data) if a.data else ''}{'-laserframe' if a.frame == 'laser' else ''}"
            f"{f'-{a.scans}scans' if a.scans else ''}.json"
        )
        write_json(REPO / "results" / "checks" / name, {k: v for k, v in r.items()})
        return 0
    if a.neff:
        exp = a.exp.removeprefix("+exp=")
        r = neff_check(exp, a.data)
        print(
            f"{exp}: resamplings per run, released {sorted(r['resamplings_released'])} (median "
            f"{r['resamplings_median'][0]:g}), ours {sorted(r['resamplings_ours'])} (median {r['resamplings_median'][1]:g}); "
            f"Mann-Whitney p {r['resamplings_mannwhitney_p']:.2g}"
        )
        print(
            f"N_eff on scans not resampled, quartiles: released {np.round(r['neff_quartiles_released'], 2).tolist()}, "
            f"ours {np.round(r['neff_quartiles_ours'], 2).tolist()}; KS p {r['neff_ks_p']:.2g}"
        )
        write_json(REPO / "results" / "checks" / f"gmapping_neff_{exp}.json", r)
        return 0
    if a.motion:
        r = motion_check()
        print(
            "| step | x mean: released / ours | y mean | theta mean | std ratio ours/released (x, y, theta) | agree |"
        )
        print("|---|---|---|---|---|---|")
        for name, c in r["cases"].items():
            means = " | ".join(f"{c['released_mean'][i]:.5f} / {c['ours_mean'][i]:.5f}" for i in range(3))
            print(f"| {name} | {means} | {', '.join(f'{v:.4f}' for v in c['std_ratio'])} | {c['agree']} |")
        write_json(REPO / "results" / "checks" / "gmapping_motion.json", r)
        return 0 if all(c["agree"] for c in r["cases"].values()) else 1
    if a.keep_only:
        keep_runs(a.exp.removeprefix("+exp="))
        return 0
    if a.matcher:
        exp = a.exp.removeprefix("+exp=")
        r = matcher_check(load_stream(compose_config([f"+exp={exp}"])))
        print("| pose | score: released / ours | log-likelihood: released / ours |")
        print("|---|---|---|")
        for i, c in enumerate(r["scores"]):
            print(
                f"| {'true' if i % 2 == 0 else 'perturbed'} | {c['released'][0]:.6f} / {c['ours'][0]:.6f} | "
                f"{c['released'][1]:.4f} / {c['ours'][1]:.4f} |"
            )
        print(
            f"largest relative difference: score {r['score_rel_diff_max']:.2e}, likelihood {r['loglik_rel_diff_max']:.2e}; "
            f"hill climbing: poses within {r['climb_pose_diff_m_max']:.4f} m, scores {r['climb_score_rel_diff_max']:.2e}"
        )
        write_json(REPO / "results" / "checks" / f"gmapping_matcher_{exp}.json", r)
        return 0
    if not (GFS if a.gfs else BINARY).is_file():
        raise FileNotFoundError(
            f"{GFS if a.gfs else BINARY}: build it first: bash eval/reference/build_gmapping.sh "
            "<openslam_gmapping clone>"
        )
    exp = a.exp.removeprefix("+exp=")
    if any(not o.startswith("data.") for o in a.data):
        raise ValueError(f"--data {a.data}: only overrides of the data config (data.<key>=<value>)")
    cfg = compose_config([f"+exp={exp}", *a.data])
    log = load_stream(cfg)
    out_root = REPO / "outputs"
    if a.gfs:
        if a.data or a.set:
            raise ValueError("--gfs runs the released tool at its own defaults on the log as it is: no --data or --set")
        clf = gfs_log(cfg, out_root)
        with ThreadPoolExecutor(a.jobs) as pool:
            runs = list(pool.map(lambda s: run_gfs_seed(cfg, log, clf, s, out_root), seeds_of(a.seeds)))
        print(f"released GMapping's gfs_nogui on {exp} ({len(log)} scans, 30 particles, its defaults)")
    else:
        params = wrapper_params(cfg, log, a.set)
        scans_file = (
            runs.cache_dir(cfg, f"{TOOL}-inputs", out_root) / f"scans{'-' + data_tag(a.data) if a.data else ''}.txt"
        )
        export_scans(log, scans_file)
        with ThreadPoolExecutor(a.jobs) as pool:
            runs = list(
                pool.map(lambda s: run_seed(cfg, log, scans_file, s, params, out_root, a.data), seeds_of(a.seeds))
            )
        print(f"released GMapping on {exp} ({len(log)} scans, {params.get('particles', 30)} particles)")
    print("| seed | processed | relations m | deg | wall s |")
    print("|---|---|---|---|---|")
    for m in runs:
        r = m["relations"]
        print(
            f"| {m['seed']} | {m['processed_scans']} | {r['trans_abs_mean_m']:.3f} | {r['rot_abs_mean_deg']:.2f} | "
            f"{m['wall_time_s']:.1f} |"
        )
    if a.keep:
        keep_runs(exp)
    return 0


def keep_runs(exp: str) -> Path:
    """Merge every finished run of ``exp`` in outputs/ into results/slam/reference/<exp>.json."""
    keep = REPO / "results" / "slam" / "reference" / f"{exp}.json"
    kept = json.loads(keep.read_text()) if keep.is_file() else {}
    for folder in runs.tool_runs(TOOL, exp, REPO / "outputs"):
        m = json.loads((folder / "metrics.json").read_text())
        kept[m["run"]] = m
    atomic_write_bytes(keep, (json.dumps(kept, sort_keys=True, default=float) + "\n").encode())
    print(f"{len(kept)} runs -> {keep}")
    return keep


if __name__ == "__main__":
    raise SystemExit(guard(main))
