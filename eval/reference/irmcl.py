"""``python -m eval.reference.irmcl +exp=fr079 train=fast localize.mode=tracking mcl.num_particles=N [--stage S]``:
the authors' IR-MCL (github.com/PRBonn/ir-mcl, their ``main.py``: their NOG, sensor model, motion model,
resampling and estimate) on our log, with our trained field, scored like our own localize runs.

Their code is set up outside the project by ``bash eval/reference/build_irmcl.sh <clone>`` (into
outputs/reference/irmcl/, git-ignored). This command writes, per start time of our protocol (the same
``localize.num_starts`` windows of ``localize.run_s`` seconds as ``irmcl_warp.localize``):

* their sequence file (``seq.json``: per scan the relative stamp, the ground-truth pose, the odometry reading
  and the full scan, no-return beams as ``max_range``, which their loader ignores; ``max_range`` = our far
  bound, so their ``far = floor(max_range)`` is ours), the base->laser transform (``b2l.txt``), the
  ground truth in TUM form, and their configuration (``loc.yml``: their pose-tracking file's values, with
  the particle count, map bounds and our field);
* our NOF (``train=<preset>``'s nof.pt) as their checkpoint (``nof.ckpt``; the same network, the layers
  renamed: ours ``head``/``tail``/``out``, theirs ``layer1``/``layer2``/``occ_out``);

runs ``main.py`` in their source folder, and reads their estimate back (``IRMCL.txt``, which their
``summary_loc`` writes: the mean of the top 80 % of the particles after resampling). Its folder is
``outputs/<exp>/reference-irmcl-<mode>-<particles>/`` with ``start<k>.tum`` (stamps of the log),
``config.yaml`` and ``metrics.json`` as a localize run has them, so ``eval.yaw_lag`` and ``eval.rescore``
read it like ours; their own evo summary (what their script prints, after 20 s) is kept per start
(``their_summary``), and their log of each start is ``start<k>.log``.

Their code fixes its own random seeds (numpy at import; the motion model's C++ generator is seeded from
``std::random_device``, so runs are not repeatable bit for bit).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from irmcl_warp.config import compose_config
from irmcl_warp.io import write_tum
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.mcl.stage import start_indices
from irmcl_warp.mcl.folders import particles_tag
from irmcl_warp.nof.folders import train_folder
from irmcl_warp.services.cli import guard
from irmcl_warp.services.data import far_bound_m, load_stream, prepare_beams
from irmcl_warp.services.metrics import localization_metrics
from irmcl_warp.services.outputs import stage_dir, write_json

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "outputs" / "reference" / "irmcl"
# their pose-tracking configuration (config/pose_tracking/loc_config_test1.yml), values kept as they are
THEIR_TRACKING = {"max_beams": 32, "L_pos": 10, "feature_size": 256, "use_skip": True, "N_samples": 256,
                  "chunk": 266496, "use_disp": False, "sensor_model": "nog", "nog_res": 0.05, "pose_tracking": True,
                  "init_noise": [0.5, 0.5, 0.0685], "grid_res": 1, "converge_thres": 2, "visualize": False,
                  "plot_loc_results": False, "map_res": 0.05}
# their evo summary line after the header "location_rmse location_ptc5 ... yaw_ptc20"
SUMMARY_KEYS = ("location_rmse_cm", "location_ptc5", "location_ptc10", "location_ptc20", "yaw_rmse_deg",
                "yaw_ptc5", "yaw_ptc10", "yaw_ptc20")


def their_checkpoint(nof_pt: Path) -> dict:
    """Our nof.pt's weights under their names: ours head.i.{0,1} (linear, batch norm) -> their layer1.{3i,3i+1},
    tail -> layer2, out -> occ_out.0 (their ReLU layers sit at 3i+2 and hold no weights)."""
    ckpt = torch.load(nof_pt, map_location="cpu", weights_only=False)
    mc = ckpt["model_config"]
    if (mc["num_freqs"], mc["width"], mc["depth"], mc["skip_after"]) != (10, 256, 8, 4):
        raise ValueError(f"{nof_pt}: their network is L=10, 256 wide, 8 deep, skip after 4; this one is {mc}")
    out = {}
    for key, value in ckpt["model"].items():
        part, *rest = key.split(".")
        if part in ("head", "tail"):
            block, sub, name = rest
            out[f"nof.{'layer1' if part == 'head' else 'layer2'}.{3 * int(block) + int(sub)}.{name}"] = value
        elif part == "out":
            out[f"nof.occ_out.0.{rest[0]}"] = value
        else:
            raise ValueError(f"{nof_pt}: unexpected weight {key}")
    return {"state_dict": out}


def export_start(log, idx: np.ndarray, far: float, folder: Path) -> int:
    """Their sequence file of the scans ``idx`` into ``folder``; returns their start index (the first scan
    with ground truth: they start the particles around it)."""
    gt_known = np.all(np.isfinite(log.ground_truth[idx]), axis=1)
    if not gt_known.any():
        raise ValueError(f"{log.source}: no ground truth in the window of scans {idx[0]}..{idx[-1]}")
    t0 = log.stamps[idx[0]]
    angles = log.info.angles_rad
    ranges = np.where(np.isfinite(log.ranges_m[idx]), log.ranges_m[idx], far)
    ranges = np.minimum(ranges, far)  # their loader sets every reading >= max_range to 0 (ignored)
    scans = [{"timestamp": float(log.stamps[i] - t0),
              "pose_gt": [float(v) for v in (log.ground_truth[i] if k else log.ground_truth[idx][gt_known][0])],
              "odom_reading": [float(v) for v in log.odom[i]],
              "range_reading": [round(float(r), 3) for r in ranges[j]]}
             for j, (i, k) in enumerate(zip(idx, gt_known))]
    doc = {"num_beams": int(len(angles)), "angle_min": float(angles[0]), "angle_max": float(angles[-1]),
           "angle_res": float(np.median(np.diff(angles))), "max_range": float(far), "scans": scans}
    atomic_write_bytes(folder / "seq.json", json.dumps(doc).encode())
    x, y, a = log.T_base_laser
    T = np.array([[np.cos(a), -np.sin(a), 0, x], [np.sin(a), np.cos(a), 0, y], [0, 0, 1, 0], [0, 0, 0, 1]])
    np.savetxt(folder / "b2l.txt", T)
    known = idx[gt_known]
    write_tum(folder / "gt.tum", log.stamps[known] - t0, log.ground_truth[known])
    return int(np.flatnonzero(gt_known)[0])


def parse_their_log(text: str) -> dict:
    """Their evo summary (after 20 s) and the time of each filter step, from what main.py prints."""
    out = {}
    lines = text.splitlines()
    for k, line in enumerate(lines):
        if line.split()[:1] == ["location_rmse"] and k + 1 < len(lines):
            try:
                values = [float(v) for v in lines[k + 1].split()]
            except ValueError:  # their evaluation failed after the header (its traceback follows)
                continue
            if len(values) == len(SUMMARY_KEYS):
                out["their_summary"] = dict(zip(SUMMARY_KEYS, values))
    costs = [float(m) for m in re.findall(r"with time cost: ([0-9.eE+-]+)s", text)]
    if costs:
        out["their_ms_per_frame_median"] = 1e3 * float(np.median(costs))
    return out


def out_folder(cfg) -> Path:
    return stage_dir(cfg, f"reference-irmcl-{cfg.localize.mode}-{particles_tag(cfg.mcl.num_particles)}").resolve()


def starts_of(cfg, log) -> np.ndarray:
    t = log.stamps - log.stamps[0]
    return np.linspace(0.0, max(t[-1] - cfg.localize.run_s, 0.0), cfg.localize.num_starts)


def prepare(cfg) -> Path:
    """Their inputs for every start into the run's folder (see the module's doc)."""
    loc, m = cfg.localize, cfg.mcl
    if loc.kidnap_at_s > 0:
        raise ValueError("localize.kidnap_at_s: their script has no kidnapping; run without it")
    nof_pt = stage_dir(cfg, train_folder(cfg)) / "nof.pt"
    if not nof_pt.is_file():
        raise FileNotFoundError(f"{nof_pt}: train the NOF first (python -m irmcl_warp.train +exp={cfg.exp} train={cfg.train.name})")
    far, out, src = far_bound_m(cfg), out_folder(cfg), BUILD / "src"
    out.mkdir(parents=True, exist_ok=True)
    torch.save(their_checkpoint(nof_pt), out / "nof.ckpt")
    # their NOG is a box of cells around the training path, the far bound and 2 m more on every side, so that
    # no sample of a ray from a particle near the path falls outside it (their lookup does not clip)
    origins = prepare_beams(cfg)["train"].T_map_laser[:, :2]
    lo, hi = origins.min(0) - far - 2, origins.max(0) + far + 2
    nog_size = [float(np.floor(lo[0])), float(np.ceil(hi[0])), float(np.floor(lo[1])), float(np.ceil(hi[1]))]
    log = load_stream(cfg)
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: localization is scored against ground truth, and this log has none")
    starts = starts_of(cfg, log)
    t = log.stamps - log.stamps[0]
    rel = lambda p: os.path.relpath(p, src)  # noqa: E731  (their script runs in their tree, here or elsewhere)
    for k in range(len(starts)):
        folder = out / f"start{k}"
        folder.mkdir(exist_ok=True)
        first = export_start(log, start_indices(t, starts, k, loc), far, folder)
        np.save(folder / "occmap.npy", np.zeros((2, 2), np.float32))  # read by their script for plots only
        conf = {**THEIR_TRACKING, "map_file": rel(folder / "occmap.npy"), "map_pose_file": rel(folder / "seq.json"),
                "data_file": rel(folder / "seq.json"), "T_b2l": rel(folder / "b2l.txt"), "map_size": nog_size,
                "gt_file": rel(folder / "gt.tum"), "result_path": rel(folder / "loc_results.npz"),
                "ckpt_path": rel(out / "nof.ckpt"), "nog_size": nog_size, "start_idx": first,
                "numParticles": int(m.num_particles), "num_reduced": int(m.num_particles)}
        atomic_write_bytes(folder / "loc.yml", json.dumps(conf, indent=1).encode())  # JSON is YAML
    OmegaConf.save(cfg, out / "config.yaml")
    settings = {**THEIR_TRACKING, "num_particles": int(m.num_particles), "nog_size": nog_size, "far_m": far,
                "run_s": loc.run_s, "num_starts": loc.num_starts, "mode": loc.mode, "nof": str(nof_pt)}
    write_json(out / "prepared.json", settings)
    print(f"prepared {len(starts)} starts in {out}")
    return out


def score(cfg) -> Path:
    """Their estimates (start<k>/IRMCL.txt) scored like our localize runs: start<k>.tum, metrics.json."""
    out, log = out_folder(cfg), load_stream(cfg)
    starts, t = starts_of(cfg, log), log.stamps - log.stamps[0]
    runs, commit = [], (BUILD / "COMMIT").read_text().split()[0] if (BUILD / "COMMIT").is_file() else "?"
    for k, t0 in enumerate(starts):
        folder, text = out / f"start{k}", (out / f"start{k}.log").read_text()
        *wall, code = (out / f"start{k}.wall").read_text().split()  # "seconds exit-code" (older runs: the code only)
        conf = json.loads((folder / "loc.yml").read_text())
        est_file = folder / "IRMCL.txt"
        if not est_file.is_file():
            raise RuntimeError(f"their main.py wrote no estimate for start {k} (exit {code}); see {out / f'start{k}.log'}")
        tum = np.loadtxt(est_file, ndmin=2)
        scans = start_indices(t, starts, k, cfg.localize)[conf["start_idx"]:]
        if len(tum) != len(scans) or not np.allclose(tum[:, 0], log.stamps[scans] - log.stamps[scans[0] - conf["start_idx"]]):
            raise RuntimeError(f"{est_file}: its {len(tum)} stamps are not those of the {len(scans)} scans it was given")
        yaw = 2 * np.arctan2(tum[:, 6], tum[:, 7])  # their quaternion (x, y, z, w) about z
        est = np.column_stack([tum[:, 1], tum[:, 2], yaw])
        write_tum(out / f"start{k}.tum", log.stamps[scans], est)
        metrics = localization_metrics(log.stamps[scans], est, log.ground_truth[scans])
        runs.append({"start_s": float(t0), "wall_s": float(wall[0]) if wall else None, "exit_code": int(code), **parse_their_log(text), **metrics})
        print(f"start {k} at {t0:.0f} s: their IR-MCL " + (f"RMSE {metrics['location_rmse_cm']:.1f} cm, "
              f"{metrics['yaw_rmse_deg']:.2f} deg" if metrics["converged"] else "did not converge"))
    ok = [r for r in runs if r["success"]]
    mean = lambda key: float(np.mean([r[key] for r in ok])) if ok else None  # noqa: E731
    settings = json.loads((out / "prepared.json").read_text())
    summary = {"implementation": f"the authors' IR-MCL (PRBonn/ir-mcl {commit}, main.py) with our NOF ({settings['nof']})",
               "weighting": "their nog", "mode": cfg.localize.mode, "num_particles": settings["num_particles"],
               "starts": len(runs), "successes": len(ok), "success_rate": len(ok) / len(runs),
               "location_rmse_cm_mean": mean("location_rmse_cm"), "yaw_rmse_deg_mean": mean("yaw_rmse_deg"),
               "time_to_converge_s_mean": mean("time_to_converge_s"),
               "their_ms_per_frame_median": float(np.median([r["their_ms_per_frame_median"] for r in runs]))}
    write_json(out / "metrics.json", {"dataset": cfg.data.name, "summary": summary, "runs": runs, "settings": settings})
    print(f"{cfg.data.name}, their IR-MCL ({cfg.localize.mode}, {settings['num_particles']} particles): success "
          f"{len(ok)}/{len(runs)}, location {summary['location_rmse_cm_mean']} cm, yaw {summary['yaw_rmse_deg_mean']} deg -> {out}")
    return out


KEPT = REPO / "results" / "checks" / "irmcl_reference"
KEEP_FILES = ("metrics.json", "config.yaml", "yaw_lag.json")


def keep(cfg, also: list[Path]) -> list[Path]:
    """Copy their scored run and the runs of ours it is set beside (``also``: localize folders) into
    results/checks/irmcl_reference/<exp>/<folder>/: metrics.json, config.yaml and yaw_lag.json (run
    ``python -m eval.yaw_lag`` on them first), which is what docs/fidelity.md reads."""
    kept = []
    for run in [out_folder(cfg), *also]:
        missing = [n for n in KEEP_FILES if not (run / n).is_file()]
        if missing:
            raise FileNotFoundError(f"{run}: no {', '.join(missing)} (score the run, then python -m eval.yaw_lag {run})")
        dest = KEPT / cfg.exp / run.name
        dest.mkdir(parents=True, exist_ok=True)
        for name in KEEP_FILES:
            atomic_write_bytes(dest / name, (run / name).read_bytes())
        kept.append(dest)
        print(f"kept {run} -> {dest.relative_to(REPO)}")
    return kept


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("overrides", nargs="*", help="Hydra overrides: +exp=<name> train=<preset> localize.* mcl.num_particles=...")
    ap.add_argument("--stage", choices=["prepare", "run", "score", "all", "keep"], default="all",
                    help="prepare: write their inputs; run: their main.py here (eval/reference/run_irmcl.sh, which a GPU "
                         "machine runs instead); score: read their estimates back; all: the three in turn; keep: copy the "
                         "scored run and the --also runs into results/checks/irmcl_reference/<exp>/")
    ap.add_argument("--also", nargs="*", type=Path, default=[], help="with --stage keep: our localize runs to keep beside theirs")
    args = ap.parse_args(argv)
    if not any(o.startswith("+exp=") for o in args.overrides):
        ap.error("give the experiment, e.g. +exp=fr079 train=fast localize.mode=tracking")
    cfg = compose_config(args.overrides)
    if args.stage in ("prepare", "all"):
        prepare(cfg)
    if args.stage in ("run", "all"):
        subprocess.run(["bash", str(Path(__file__).with_name("run_irmcl.sh")), str(out_folder(cfg))], check=True)
    if args.stage in ("score", "all"):
        score(cfg)
    if args.stage == "keep":
        keep(cfg, args.also)


if __name__ == "__main__":
    guard(main)
