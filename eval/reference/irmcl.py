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
``outputs/<exp>/reference_irmcl/<mode>-<particles>-<digest>/`` with ``start<k>.tum`` (stamps of the log),
``config.yaml`` and ``metrics.json`` as a localize run has them, so ``eval.yaw_lag`` and ``eval.rescore``
read it like ours; their own evo summary (what their script prints, after 20 s) is kept per start
(``their_summary``), and their log of each start is ``start<k>.log``.

Their code fixes its own random seeds (numpy at import; the motion model's C++ generator is seeded from
``std::random_device``, so runs are not repeatable bit for bit).

The field itself: ``--stage synthesis`` scores our field with their evaluation (their dataset class, renderer
and metrics, through eval/reference/irmcl_eval_driver.py) on our test split; ``--stage nof-data`` writes our
split as their training data for ``bash eval/reference/train_irmcl.sh`` (their train.py and recipe), and
``--stage nof-score`` scores the field it trains by their evaluation and ours. ``--stage keep`` copies what
docs/fidelity.md reads into results/checks/irmcl_reference/<exp>/.
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
from irmcl_warp.mcl.stage import start_indices, start_times
from irmcl_warp.services.cli import guard
from irmcl_warp.services.data import far_bound_m, load_stream, prepare_beams
from irmcl_warp.services.metrics import localization_metrics
from irmcl_warp import runs
from irmcl_warp.runs import file_digest
from irmcl_warp.services.outputs import write_json

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "outputs" / "reference" / "irmcl"
# their pose-tracking configuration (config/pose_tracking/loc_config_test1.yml), values kept as they are
THEIR_TRACKING = {
    "max_beams": 32,
    "L_pos": 10,
    "feature_size": 256,
    "use_skip": True,
    "N_samples": 256,
    "chunk": 266496,
    "use_disp": False,
    "sensor_model": "nog",
    "nog_res": 0.05,
    "pose_tracking": True,
    "init_noise": [0.5, 0.5, 0.0685],
    "grid_res": 1,
    "converge_thres": 2,
    "visualize": False,
    "plot_loc_results": False,
    "map_res": 0.05,
}
# their evo summary line after the header "location_rmse location_ptc5 ... yaw_ptc20"
SUMMARY_KEYS = (
    "location_rmse_cm",
    "location_ptc5",
    "location_ptc10",
    "location_ptc20",
    "yaw_rmse_deg",
    "yaw_ptc5",
    "yaw_ptc10",
    "yaw_ptc20",
)


def se2_matrix(x: float, y: float, yaw: float) -> np.ndarray:
    """The 3x3 homogeneous transform of a 2D pose (their datasets' ``transform_matrix``: [:2, :3] is [R | t])."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


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


def our_checkpoint(their_ckpt: Path, near_m: float, far_m: float) -> dict:
    """Their checkpoint's network (their names, as their train.py saves it through pytorch-lightning) as our
    nof.pt: the inverse of ``their_checkpoint``."""
    sd = torch.load(their_ckpt, map_location="cpu", weights_only=False)
    sd = sd.get("state_dict", sd)
    model = {}
    for key, value in sd.items():
        if not key.startswith("nof."):
            continue
        part, *rest = key.removeprefix("nof.").split(".")
        if part in ("layer1", "layer2"):
            block, sub = divmod(int(rest[0]), 3)
            model[f"{'head' if part == 'layer1' else 'tail'}.{block}.{sub}.{rest[1]}"] = value
        elif part == "occ_out":
            model[f"out.{rest[1]}"] = value
    return {
        "model": model,
        "model_config": {"num_freqs": 10, "width": 256, "depth": 8, "skip_after": 4},
        "near_m": near_m,
        "far_m": far_m,
        "train_preset": "the authors' train.py",
        "source": str(their_ckpt),
    }


def export_start(log, idx: np.ndarray, far_m: float, folder: Path) -> int:
    """Their sequence file of the scans ``idx`` into ``folder``; returns their start index (the first scan
    with ground truth: they start the particles around it)."""
    gt_known = np.all(np.isfinite(log.ground_truth[idx]), axis=1)
    if not gt_known.any():
        raise ValueError(f"{log.source}: no ground truth in the window of scans {idx[0]}..{idx[-1]}")
    t0 = log.stamps[idx[0]]
    angles = log.info.angles_rad
    ranges = np.where(np.isfinite(log.ranges_m[idx]), log.ranges_m[idx], far_m)
    ranges = np.minimum(ranges, far_m)  # their loader sets every reading >= max_range to 0 (ignored)
    scans = [
        {
            "timestamp": float(log.stamps[i] - t0),
            "pose_gt": [float(v) for v in (log.ground_truth[i] if k else log.ground_truth[idx][gt_known][0])],
            "odom_reading": [float(v) for v in log.odom[i]],
            "range_reading": [round(float(r), 3) for r in ranges[j]],
        }
        for j, (i, k) in enumerate(zip(idx, gt_known))
    ]
    doc = {
        "num_beams": int(len(angles)),
        "angle_min": float(angles[0]),
        "angle_max": float(angles[-1]),
        "angle_res": float(np.median(np.diff(angles))),
        "max_range": float(far_m),
        "scans": scans,
    }
    atomic_write_bytes(folder / "seq.json", json.dumps(doc).encode())
    T = np.eye(4)  # their sensor model composes 4x4 particle poses with it
    T[np.ix_([0, 1, 3], [0, 1, 3])] = se2_matrix(*log.T_base_laser)
    np.savetxt(folder / "b2l.txt", T)
    known = idx[gt_known]
    write_tum(folder / "gt.tum", log.stamps[known] - t0, log.ground_truth[known])
    return int(np.flatnonzero(gt_known)[0])


def export_split(test, far_m: float, path: Path) -> None:
    """One of our splits (a BeamSet) as their dataset's <split>.json: per scan the laser's 3x3 pose
    (``transform_matrix``) and the ranges, every beam ours does not score (no return, beyond far) at
    ``max_range`` = far, which their loader marks invalid (>= max_range). ``angle_max`` lies half a step
    below the end, so that their ``arange(angle_min, angle_max, angle_res)`` has one direction per beam."""
    a = test.angles_rad
    res = float(np.median(np.diff(a)))
    ranges = np.where(test.valid & np.isfinite(test.ranges_m), test.ranges_m, far_m)
    scans = []
    for pose, r in zip(test.T_map_laser, ranges):
        scans.append(
            {
                "transform_matrix": se2_matrix(*pose).tolist(),
                "odom": [0.0, 0.0, 0.0],
                "range_readings": [round(float(v), 4) for v in r],
            }
        )
    doc = {
        "num_beams": int(len(a)),
        "angle_min": float(a[0]),
        "angle_max": float(a[0] + res * (len(a) - 0.5)),
        "angle_res": res,
        "max_range": float(far_m),
        "scans": scans,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, json.dumps(doc).encode())


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


def trained(cfg) -> Path:
    """The finished training run of ``cfg``'s settings (``train=<preset>``): its nof.pt is the field they use."""
    return runs.require(runs.identify(cfg, "train"))


def out_folder(cfg, repeat: int = 0) -> Path:
    """outputs/<exp>/reference_irmcl/<mode>-<N>[-run<repeat>]-<digest>/ (irmcl_warp.runs.tool_dir): their filter
    seeds itself from the machine (std::random_device), so a repeat is another draw of the same run."""
    label = f"{cfg.localize.mode}-{cfg.mcl.num_particles}" + (f"-run{repeat}" if repeat else "")
    settings = {
        "localize": OmegaConf.to_container(cfg.localize),
        "particles": int(cfg.mcl.num_particles),
        "reduce_to": int(cfg.mcl.reduce_to),
        "field": runs.identify(cfg, "train").id,
        "repeat": repeat,
    }
    return runs.tool_dir(cfg.exp, "reference_irmcl", label, settings).resolve()


def their_field(cfg, out: Path) -> Path:
    """The nof.pt of ``train=<preset>``'s finished run, written as their checkpoint out/nof.ckpt when that is
    missing or older; returns the nof.pt."""
    nof_pt = trained(cfg) / "nof.pt"
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "nof.ckpt").is_file() or (out / "nof.ckpt").stat().st_mtime < nof_pt.stat().st_mtime:
        torch.save(their_checkpoint(nof_pt), out / "nof.ckpt")
    return nof_pt


def prepare(cfg, repeat: int = 0) -> Path:
    """Their inputs for every start into the run's folder (see the module's doc)."""
    loc, m = cfg.localize, cfg.mcl
    if loc.kidnap_at_s > 0:
        raise ValueError("localize.kidnap_at_s: their script has no kidnapping; run without it")
    far_m, out, src = far_bound_m(cfg), out_folder(cfg, repeat), BUILD / "src"
    nof_pt = their_field(cfg, out)
    # their NOG is a box of cells around the training path, the far bound and 2 m more on every side, so that
    # no sample of a ray from a particle near the path falls outside it (their lookup does not clip)
    origins = prepare_beams(cfg)["train"].T_map_laser[:, :2]
    lo, hi = origins.min(0) - far_m - 2, origins.max(0) + far_m + 2
    nog_size = [float(np.floor(lo[0])), float(np.ceil(hi[0])), float(np.floor(lo[1])), float(np.ceil(hi[1]))]
    log = load_stream(cfg)
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: localization is scored against ground truth, and this log has none")
    t = log.stamps - log.stamps[0]
    starts = start_times(t, loc)
    rel = lambda p: os.path.relpath(p, src)  # noqa: E731  (their script runs in their tree, here or elsewhere)
    for k in range(len(starts)):
        folder = out / f"start{k}"
        folder.mkdir(exist_ok=True)
        first = export_start(log, start_indices(t, starts, k, loc), far_m, folder)
        np.save(folder / "occmap.npy", np.zeros((2, 2), np.float32))  # read by their script for plots only
        conf = {
            **THEIR_TRACKING,
            "map_file": rel(folder / "occmap.npy"),
            "map_pose_file": rel(folder / "seq.json"),
            "data_file": rel(folder / "seq.json"),
            "T_b2l": rel(folder / "b2l.txt"),
            "map_size": nog_size,
            "gt_file": rel(folder / "gt.tum"),
            "result_path": rel(folder / "loc_results.npz"),
            "ckpt_path": rel(out / "nof.ckpt"),
            "nog_size": nog_size,
            "start_idx": first,
            "numParticles": int(m.num_particles),
            "num_reduced": int(m.num_particles),
        }
        if loc.mode == "global":  # their global file: uniform over the map's box (any heading), the heaviest
            # num_reduced kept 20 s in; the box here is the training path's, 1 m more on every side
            box = origins.min(0) - 1.0, origins.max(0) + 1.0
            conf.update(
                pose_tracking=False,
                num_reduced=int(m.reduce_to) if m.reduce_to > 0 else int(m.num_particles),
                map_size=[float(box[0][0]), float(box[1][0]), float(box[0][1]), float(box[1][1])],
            )
        atomic_write_bytes(folder / "loc.yml", json.dumps(conf, indent=1).encode())  # JSON is YAML
    OmegaConf.save(cfg, out / "config.yaml")
    settings = {
        **THEIR_TRACKING,
        "num_particles": int(m.num_particles),
        "nog_size": nog_size,
        "far_m": far_m,
        "run_s": loc.run_s,
        "num_starts": loc.num_starts,
        "mode": loc.mode,
        "nof": str(nof_pt),
    }
    write_json(out / "prepared.json", settings)
    print(f"prepared {len(starts)} starts in {out}")
    return out


def score(cfg, repeat: int = 0) -> Path:
    """Their estimates (start<k>/IRMCL.txt) scored like our localize runs: start<k>.tum, metrics.json."""
    out, log = out_folder(cfg, repeat), load_stream(cfg)
    t = log.stamps - log.stamps[0]
    starts = start_times(t, cfg.localize)
    runs, commit = [], (BUILD / "COMMIT").read_text().split()[0] if (BUILD / "COMMIT").is_file() else "?"
    for k, t0 in enumerate(starts):
        folder, text = out / f"start{k}", (out / f"start{k}.log").read_text()
        *wall, code = (out / f"start{k}.wall").read_text().split()  # "seconds exit-code" (older runs: the code only)
        conf = json.loads((folder / "loc.yml").read_text())
        est_file = folder / "IRMCL.txt"
        if not est_file.is_file():
            raise RuntimeError(
                f"their main.py wrote no estimate for start {k} (exit {code}); see {out / f'start{k}.log'}"
            )
        tum = np.loadtxt(est_file, ndmin=2)
        scans = start_indices(t, starts, k, cfg.localize)[conf["start_idx"] :]
        if len(tum) != len(scans) or not np.allclose(
            tum[:, 0], log.stamps[scans] - log.stamps[scans[0] - conf["start_idx"]]
        ):
            raise RuntimeError(
                f"{est_file}: its {len(tum)} stamps are not those of the {len(scans)} scans it was given"
            )
        yaw = 2 * np.arctan2(tum[:, 6], tum[:, 7])  # their quaternion (x, y, z, w) about z
        est = np.column_stack([tum[:, 1], tum[:, 2], yaw])
        write_tum(out / f"start{k}.tum", log.stamps[scans], est)
        metrics = localization_metrics(log.stamps[scans], est, log.ground_truth[scans])
        runs.append(
            {
                "start_s": float(t0),
                "wall_s": float(wall[0]) if wall else None,
                "exit_code": int(code),
                **parse_their_log(text),
                **metrics,
            }
        )
        print(
            f"start {k} at {t0:.0f} s: their IR-MCL "
            + (
                f"RMSE {metrics['location_rmse_cm']:.1f} cm, {metrics['yaw_rmse_deg']:.2f} deg"
                if metrics["converged"]
                else "did not converge"
            )
        )
    ok = [r for r in runs if r["success"]]
    mean = lambda key: float(np.mean([r[key] for r in ok])) if ok else None  # noqa: E731
    settings = json.loads((out / "prepared.json").read_text())
    summary = {
        "implementation": f"the authors' IR-MCL (PRBonn/ir-mcl {commit}, main.py) with our NOF ({settings['nof']})",
        "weighting": "their nog",
        "mode": cfg.localize.mode,
        "num_particles": settings["num_particles"],
        "starts": len(runs),
        "successes": len(ok),
        "success_rate": len(ok) / len(runs),
        "location_rmse_cm_mean": mean("location_rmse_cm"),
        "yaw_rmse_deg_mean": mean("yaw_rmse_deg"),
        "time_to_converge_s_mean": mean("time_to_converge_s"),
        "their_ms_per_frame_median": float(np.median([r["their_ms_per_frame_median"] for r in runs])),
    }
    write_json(out / "metrics.json", {"dataset": cfg.data.name, "summary": summary, "runs": runs, "settings": settings})
    print(
        f"{cfg.data.name}, their IR-MCL ({cfg.localize.mode}, {settings['num_particles']} particles): success "
        f"{len(ok)}/{len(runs)}, location {summary['location_rmse_cm_mean']} cm, yaw {summary['yaw_rmse_deg_mean']} deg -> {out}"
    )
    return out


def our_synthesis(cfg, nof_pt: Path) -> tuple[dict | None, str | None]:
    """Our synthesis figures of this very field: from its finished run, else from the kept record of the same
    settings (results/nof/<exp>.json) when the kept training record's validation figures are the checkpoint's own."""
    ident = runs.identify(cfg, "synthesis")
    folder = runs.finished(ident)
    if folder is not None:
        doc, where = json.loads((folder / "metrics.json").read_text()), str(folder)
    else:
        from eval.results.records import kept

        recs = kept(("train", "synthesis"))
        same = runs.settings_id(OmegaConf.to_container(cfg, resolve=True), "synthesis")
        synth = next((r for r in recs if r.stage == "synthesis" and r.exp == cfg.exp and r.settings_id == same), None)
        train_id = runs.settings_id(OmegaConf.to_container(cfg, resolve=True), "train")
        train = next((r for r in recs if r.stage == "train" and r.exp == cfg.exp and r.settings_id == train_id), None)
        val = torch.load(nof_pt, map_location="cpu", weights_only=False).get("val")
        if not (train and synth and val and train.get("val") == val):
            return None, None
        doc, where = synth, f"results/nof/{cfg.exp}.json ({synth.label}; same validation figures as {nof_pt})"
    nof = next((m for m in doc["methods"].values() if m.get("kind") == "nof"), None)
    return ({k: nof[k] for k in ("mae_m", "accuracy_pct", "chamfer_m", "fscore_pct")} if nof else None), where


def their_evaluation(cfg, ckpt: Path, out: Path) -> dict:
    """Their dataset class, render_rays and error_metrics on our test split, with the field ``ckpt`` (their
    checkpoint format), through our driver (their eval.py prints 2 decimals); CPU or GPU, as torch finds."""
    done_file = out / "their_eval.json"
    if done_file.is_file() and json.loads(done_file.read_text()).get("checkpoint_sha256") == file_digest(ckpt):
        print(f"{done_file}: their evaluation of this checkpoint is there (made here or on a GPU machine): kept")
        return {k: v for k, v in json.loads(done_file.read_text()).items() if k != "per_scan"}
    export_split(prepare_beams(cfg)["test"], far_bound_m(cfg), out / "data" / "test.json")
    # their dataset class, render_rays and error_metrics through our driver (their eval.py prints 2 decimals)
    driver = BUILD / "src" / "irmcl_eval_driver.py"
    atomic_write_bytes(driver, Path(__file__).with_name("irmcl_eval_driver.py").read_bytes())
    args = [
        str(BUILD / "venv" / "bin" / "python"),
        driver.name,
        str(out / "data"),
        str(ckpt),
        str(out / "their_eval.json"),
    ]
    done = subprocess.run(args, cwd=BUILD / "src", capture_output=True, text=True)
    (out / "eval.log").write_text(done.stdout + done.stderr)
    if done.returncode != 0 or not (out / "their_eval.json").is_file():
        raise RuntimeError(f"their evaluation failed (exit {done.returncode}); see {out / 'eval.log'}")
    doc = json.loads(done_file.read_text())
    atomic_write_bytes(done_file, json.dumps({**doc, "checkpoint_sha256": file_digest(ckpt)}).encode())
    return {k: v for k, v in doc.items() if k != "per_scan"}


def their_synthesis(cfg) -> Path:
    """Their evaluation (eval.py's metrics, the paper's Table I) on our test split with our field, on the CPU:
    outputs/<exp>/reference_irmcl_synthesis/<preset>-<digest>/metrics.json holds their four figures beside our
    synthesis stage's figures of the same field and split (from its run, when it was made)."""
    out = runs.tool_dir(cfg.exp, "reference_irmcl_synthesis", cfg.train.name, runs.identify(cfg, "train").id).resolve()
    nof_pt = their_field(cfg, out)
    theirs = their_evaluation(cfg, out / "nof.ckpt", out)
    ours, ours_from = our_synthesis(cfg, nof_pt)
    doc = {
        "dataset": cfg.data.name,
        "nof": str(nof_pt),
        "far_m": far_bound_m(cfg),
        "their_eval": theirs,
        "ours": ours,
        "ours_from": ours_from,
    }
    OmegaConf.save(cfg, out / "config.yaml")
    write_json(out / "metrics.json", doc)
    print(
        f"{cfg.data.name}, {cfg.train.name}: their eval.py MAE {theirs['mae_m']:.3f} m, Chamfer {theirs['chamfer_m']:.3f} m, "
        f"F {theirs['fscore_pct']:.1f} %"
        + (
            f"; ours MAE {ours['mae_m']:.3f} m, Chamfer {ours['chamfer_m']:.3f} m, F {ours['fscore_pct']:.1f} %"
            if ours
            else "; ours not run"
        )
        + f" -> {out}"
    )
    return out


def nof_folder(cfg) -> Path:
    """Their training recipe on our split (eval/reference/train_irmcl.sh): one per experiment and split."""
    return runs.tool_dir(
        cfg.exp, "reference_irmcl_nof", "their-recipe", {"split": cfg.data.split, "val_scans": cfg.train.val_scans}
    ).resolve()


def nof_data(cfg) -> Path:
    """Our split as their training data (data/train.json, val.json: our trainer's evenly spread validation
    scans, test.json) for eval/reference/train_irmcl.sh."""
    out, far_m, sets = nof_folder(cfg), far_bound_m(cfg), prepare_beams(cfg)
    val = sets["val"]
    val = val.subset(np.linspace(0, len(val) - 1, min(len(val), cfg.train.val_scans)).round().astype(int))
    for name, beams in (("train", sets["train"]), ("val", val), ("test", sets["test"])):
        export_split(beams, far_m, out / "data" / f"{name}.json")
    print(
        f"{cfg.data.name}: their training data ({len(sets['train'])} / {len(val)} / {len(sets['test'])} scans) in {out / 'data'}"
    )
    return out


def their_val_curve(log_text: str) -> list[dict]:
    """Per epoch, the validation figures their progress bar shows at the epoch's end (3 decimals)."""
    last = {}
    for line in log_text.replace("\r", "\n").splitlines():
        m = re.search(r"Epoch (\d+): 100%.*val/avg_error=([0-9.]+).*val/cd=([0-9.]+).*val/fscore=([0-9.na]+)", line)
        if m:
            last[int(m.group(1))] = {
                "epoch": int(m.group(1)) + 1,
                "val_mae_m": float(m.group(2)),
                "val_chamfer_m": float(m.group(3)),
                "val_fscore": float(m.group(4)) if m.group(4) != "nan" else None,
            }
    return [last[k] for k in sorted(last)]


def nof_score(cfg) -> Path:
    """Their trained field (logs/nof/version_0/checkpoints/best.ckpt, brought back from train_irmcl.sh) scored
    on our test split by their evaluation and by ours (eval.synthesis's renderer and metrics)."""
    from irmcl_warp.nof.synthesis import nof_ranges
    from irmcl_warp.services.metrics import scan_synthesis_metrics

    out = nof_folder(cfg)
    ckpts = sorted(out.glob("logs/nof/version_*/checkpoints/best.ckpt"))
    if not ckpts:
        raise FileNotFoundError(
            f"{out}/logs: no best.ckpt (run bash eval/reference/train_irmcl.sh {out / 'data'} EPOCHS)"
        )
    ckpt = ckpts[-1]
    theirs = their_evaluation(cfg, ckpt, out)
    test, far_m = prepare_beams(cfg)["test"], far_bound_m(cfg)
    ours_pt = out / "nof.pt"
    torch.save(our_checkpoint(ckpt, 0.02, far_m), ours_pt)
    pred, _ = nof_ranges(ours_pt, test, cfg)
    ours = scan_synthesis_metrics(pred, test.ranges_m, test.valid, test.angles_rad)
    meta = torch.load(ckpt, map_location="cpu", weights_only=False)
    log = out / "train.log"  # what train_irmcl.sh printed (brought back with the checkpoints)
    doc = {
        "dataset": cfg.data.name,
        "checkpoint": str(ckpt),
        "best_epoch": int(meta.get("epoch", -1)) + 1,
        "their_val_per_epoch": their_val_curve(log.read_text()) if log.is_file() else None,
        "their_eval": theirs,
        "our_eval": {k: ours[k] for k in ("mae_m", "accuracy_pct", "chamfer_m", "fscore_pct")},
    }
    OmegaConf.save(cfg, out / "config.yaml")
    write_json(out / "metrics.json", doc)
    print(
        f"{cfg.data.name}, their recipe (best epoch {doc['best_epoch']}): their evaluation MAE {theirs['mae_m']:.3f} m, "
        f"Chamfer {theirs['chamfer_m']:.3f} m; ours MAE {ours['mae_m']:.3f} m, Chamfer {ours['chamfer_m']:.3f} m -> {out}"
    )
    return out


KEEP_ARTIFACTS = ("yaw_lag.json",)  # the analyses docs/fidelity.md reads beside a run's metrics


def keep(cfg, also: list[Path], repeat: int = 0) -> Path:
    """Keep their scored run and the runs of ours it is set beside (``also``: localize run folders) as records
    of the check study results/checks/irmcl_reference.json, with yaw_lag.json as an artifact (run
    ``python -m eval.analyses.yaw_lag`` on them first), which is what docs/fidelity.md reads; and the log's field checks
    (``--stage synthesis``, ``nof-score``) when they were made."""
    from eval.results.records import keep_check

    entries = []
    for run, stage in [(out_folder(cfg, repeat), "reference_irmcl"), *((p, "localize") for p in also)]:
        missing = [n for n in ("metrics.json", "config.yaml", *KEEP_ARTIFACTS) if not (run / n).is_file()]
        if missing:
            raise FileNotFoundError(
                f"{run}: no {', '.join(missing)} (score the run, then python -m eval.analyses.yaw_lag {run})"
            )
        entries.append((run, stage, KEEP_ARTIFACTS, repeat if stage == "reference_irmcl" else 0))
    for run in runs.tool_runs("reference_irmcl_synthesis", cfg.exp):
        entries.append((run, "reference_irmcl_synthesis", (), 0))
    if (nof_folder(cfg) / "metrics.json").is_file():
        entries.append((nof_folder(cfg), "reference_irmcl_nof", (), 0))
    return keep_check("irmcl_reference", cfg.exp, entries)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "overrides", nargs="*", help="Hydra overrides: +exp=<name> train=<preset> localize.* mcl.num_particles=..."
    )
    ap.add_argument(
        "--stage",
        choices=["prepare", "run", "score", "all", "keep", "synthesis", "nof-data", "nof-score"],
        default="all",
        help="prepare: write their inputs; run: their main.py here (eval/reference/run_irmcl.sh, which a GPU "
        "machine runs instead); score: read their estimates back; all: the three in turn; keep: copy the "
        "scored run and the --also runs as records of results/checks/irmcl_reference.json; synthesis: their evaluation "
        "(eval.py's metrics, Table I) on our test split with our field (CPU; needs open3d in their venv); nof-data: "
        "our split as their training data (for train_irmcl.sh); nof-score: their trained field on our "
        "test split, by their evaluation and ours",
    )
    ap.add_argument(
        "--also", nargs="*", type=Path, default=[], help="with --stage keep: our localize runs to keep beside theirs"
    )
    ap.add_argument(
        "--repeat",
        type=int,
        default=0,
        help="K > 0: another draw of their (self-seeding) filter, in the folder ...-run<K>",
    )
    args = ap.parse_args(argv)
    if not any(o.startswith("+exp=") for o in args.overrides):
        ap.error("give the experiment, e.g. +exp=fr079 train=fast localize.mode=tracking")
    cfg = compose_config(args.overrides)
    if args.stage in ("prepare", "all"):
        prepare(cfg, args.repeat)
    if args.stage in ("run", "all"):
        subprocess.run(
            ["bash", str(Path(__file__).with_name("run_irmcl.sh")), str(out_folder(cfg, args.repeat))], check=True
        )
    if args.stage in ("score", "all"):
        score(cfg, args.repeat)
    if args.stage == "keep":
        keep(cfg, args.also, args.repeat)
    if args.stage == "synthesis":
        their_synthesis(cfg)
    if args.stage == "nof-data":
        nof_data(cfg)
    if args.stage == "nof-score":
        nof_score(cfg)


if __name__ == "__main__":
    guard(main)
