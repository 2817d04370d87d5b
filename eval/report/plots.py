"""``python -m eval.plots``: every figure, generated from the run records (results/ and outputs/, one of yours
replacing a kept record of the same settings) into docs/figures/.

* slam_particles_vs_success_<dataset>.png: GMapping's converged runs (relations error < 0.15 m) over seeds
  against the particle count, per proposal and resampling (Grisetti et al. 2007, Fig. 7 style);
* ../maps/<exp>.png: the map of each log's best default paper-proposal run.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

from eval.results.queries import CONVERGED_M, slam_variant
from eval.results.records import REPO, kept_map, load
from irmcl_warp.services.outputs import save_figure
from irmcl_warp.services.cli import guard


def particles_vs_success(runs: list, dataset: str, out: Path) -> Path | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = defaultdict(lambda: defaultdict(list))
    for m in runs:
        if m["dataset"] == dataset and isinstance(m.get("relations"), dict) and not slam_variant(m):
            where = "" if str(m.get("device", "")).startswith("cuda") else f" ({m.get('device', '?')})"
            groups[f"{m['proposal']} + {m['resample']}{where}"][m["particles"]].append(
                m["relations"]["trans_abs_mean_m"]
            )
    if not groups:
        return None
    fig, ax = plt.subplots(figsize=(7, 4.2))
    markers = "osD^v"
    for i, (name, by_n) in enumerate(sorted(groups.items())):
        ns = sorted(by_n)
        rate = [100 * sum(e < CONVERGED_M for e in by_n[n]) / len(by_n[n]) for n in ns]
        (line,) = ax.plot(ns, rate, markers[i % len(markers)] + "-", label=name, alpha=0.85)
        for n, r in zip(ns, rate):  # k/n under each point, staggered per series
            ax.annotate(
                f"{sum(e < CONVERGED_M for e in by_n[n])}/{len(by_n[n])}",
                (n, r),
                textcoords="offset points",
                xytext=(0, -11 - 9 * i),
                ha="center",
                fontsize=7,
                color=line.get_color(),
            )
    ax.set_xscale("log")
    ax.minorticks_off()
    ax.set_xticks(sorted({n for g in groups.values() for n in g}))
    ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.set_ylim(-40, 105)
    ax.set_yticks(range(0, 101, 20))
    ax.set_xlabel("particles")
    ax.set_ylabel(f"converged seeds (%), relations error < {CONVERGED_M} m")
    ax.set_title(f"GMapping on {dataset}: success vs particle count")
    ax.legend(fontsize=8, loc="center right")
    ax.grid(alpha=0.3)
    return save_figure(fig, out)


def kidnapped_run(exp: str, name: str, metrics: dict, out: Path) -> Path | None:
    """Position error over time of every method on the first run of a kidnap scenario (``first_run`` of its
    metrics), the kidnapping and the paper pipeline's relocalizations marked."""
    first = metrics.get("first_run", {})
    methods = [m for m in first if isinstance(first[m], dict)]
    if len(methods) < 2:  # a figure compares methods (ablation runs of one method are left out)
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = np.asarray(first["stamps_s"])
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for method in sorted(methods):
        err = np.array([np.nan if e is None else e for e in first[method]["error_m"]])
        ax.plot(t, err, label=method, lw=1.4)
        if method == "paper":
            for r in first[method]["relocalized_at"]:
                ax.axvline(t[r], color="C2", ls=":", lw=1)
    if first["kidnap_index"] > 0:
        ax.axvline(t[first["kidnap_index"]], color="k", lw=1.5, label="kidnapped")
    ax.set_yscale("log")
    ax.set_ylim(0.01, 100)
    ax.axhline(0.5, color="gray", lw=0.8, ls="--")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position error (m)")
    ax.set_title(f"{exp}, {name}: run 0 (dotted: the pipeline's relocalizations)")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return save_figure(fig, out)


def best_maps(runs: list, out: Path) -> list[Path]:
    """docs/maps/<exp>.png: the map of each log's best default paper-proposal run (lowest relations error;
    a converged run first, then 30 particles, or the most there are), copied from its run folder in outputs/ or its
    kept map (results/slam/maps/<exp>/<run>.png, kept by ``python -m eval.keep --maps``)."""
    import shutil

    best = {}
    for m in runs:
        if (
            m.get("proposal") != "paper"
            or m.get("resample") != "selective"
            or slam_variant(m)
            or not isinstance(m.get("relations"), dict)
        ):
            continue
        err = m["relations"]["trans_abs_mean_m"]
        key = (err < CONVERGED_M, m["particles"] == 30, m["particles"], -err)  # a converged run, 30 particles if any
        if m.exp not in best or key > best[m.exp][0]:
            best[m.exp] = (key, m)
    made = []
    for exp, (_, m) in sorted(best.items()):
        src = [p for p in ((m.path / "map.png") if m.path else None, kept_map(m)) if p is not None and p.exists()]
        if src:
            out.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src[0], out / f"{exp}.png")
            made.append(out / f"{exp}.png")
    return made


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.plots")
    ap.add_argument("--out", default=str(REPO / "docs" / "figures"))
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = load(("slam",))
    made = [
        p
        for ds in ("intel", "fr079", "mit_csail", "mit_killian")
        if (p := particles_vs_success(runs, ds, out / f"slam_particles_vs_success_{ds}.png")) is not None
    ]
    made += best_maps(runs, out.parent / "maps")
    for m in sorted(load(("globloc",)), key=lambda r: (r.exp, r.label)):
        name = m.setting("globloc.scenario")
        if (
            m.get("kidnap_at_s", m.get("settings", {}).get("kidnap_at_s", 0)) > 0
            and (p := kidnapped_run(m.exp, name, m, out / f"{m.exp}.png")) is not None
        ):
            made.append(p)
    for p in made:
        print(f"-> {p}")
    if not made:
        raise SystemExit("no SLAM results under results/slam or outputs (run python -m irmcl_warp.slam)")


if __name__ == "__main__":
    guard(main)
