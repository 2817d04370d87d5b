"""``python -m eval.bench mcl [--device cuda] [--particles 10000 100000 1000000] [--nog PATH.npz]``

Side-by-side speed of one full MCL step (motion + weighting + resampling + estimate, ``mcl`` defaults:
32 beams x 256 samples on the NOG, resampling every step as IR-MCL's code, the top-80 % estimate) for
Warp kernel variants, against IR-MCL's weighting formulated as the authors do in torch (every sample,
chunks of 500 particles; irmcl_warp/reference/weighting.py) on the same device, in one run:

* ``warp``: the same formulation as the torch reference (every sample, one node load at a time);
* ``warp+et``: early termination once the transmittance is below 1e-3;
* ``+b4``: four node loads in flight per beam before compositing (``mcl.march_batch``; same result);
* ``+beam``: GPU threads ordered by beam, then particle (``mcl.march_order``);
* ``warp+et+skip``: nodes below p_occ 0.01 read as empty and jumped over (``mcl.empty_below``);
* ``likelihood_field``, ``beam_model``: AMCL's grid models on the NOG read as an occupancy grid (the baseline);
* ``table``, ``table360``: ``mcl.weighting=nog_table``, the ``warp+et`` march run once from every NOG node at
  720 (360) headings, read per beam from that table (an approximation: each row also gives the table's build
  time and how far its ranges lie from the march's on the benchmark's particles after the steps);

each with the step's launches replayed as one captured graph (``graph``, mcl.step_graph=on) and launched
one by one (``eager``), side by side (``--step-graph`` picks one). ``--host-split`` also times a captured step's
parts apart (``host_split``: the graph replayed and waited for, back to back, the upload, the read-back), so that the
host's part of a step is measured, not guessed. ``DEFAULT_VARIANT`` names the one
``mcl``'s defaults run.

The NOG is ``--nog`` (a baked outputs/<exp>/nog/nog-*.npz), else the simulator's walls rasterised at
5 cm (no data needed). Particles start uniform over the free nodes (a global localization's first
steps); the measured scan is rendered from a free pose plus noise. Prints a table and writes
outputs/bench/mcl-<device>.json. Absolute times count only from a GPU; on a CPU read the ratios.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np
import torch
import warp as wp

from eval.bench.timing import record_path, repeated, step_ms_fields, time_per_call
from irmcl_warp.mcl import MCLConfig
from irmcl_warp.nog import NOG
from irmcl_warp.services.filters import WeightingMaps, build_filter, nog_table_settings
from irmcl_warp.services import table_cache
from irmcl_warp.services.outputs import write_json
from irmcl_warp.reference.weighting import nog_log_weights_torch
from irmcl_warp.kernels import pick_device
from irmcl_warp.config import compose_config
from irmcl_warp.sim import simulate
from irmcl_warp.kernels import SIM
from irmcl_warp.kernels import WEIGHTING


def _march(**settings) -> dict:
    """A variant of the paper's march (``nog_raymarch``; the default weighting is its range table)."""
    return dict(weighting="nog_raymarch", **settings)


VARIANTS = {
    "warp": _march(t_min=0.0, empty_below=0.0, march_batch=1, march_order="particle"),
    "warp+et": _march(t_min=1e-3, empty_below=0.0, march_batch=1, march_order="particle"),
    "warp+et+b4": _march(t_min=1e-3, empty_below=0.0, march_batch=4, march_order="particle"),
    "warp+et+beam": _march(t_min=1e-3, empty_below=0.0, march_batch=1, march_order="beam"),
    "warp+et+b4+beam": _march(t_min=1e-3, empty_below=0.0, march_batch=4, march_order="beam"),
    "warp+et+skip": _march(t_min=1e-3, empty_below=0.01, march_batch=1, march_order="particle"),
    "warp+et+skip+beam": _march(t_min=1e-3, empty_below=0.01, march_batch=1, march_order="beam"),
    "table": dict(weighting="nog_table", t_min=1e-3, empty_below=0.0, table_angles=720),
    "table360": dict(weighting="nog_table", t_min=1e-3, empty_below=0.0, table_angles=360),
    "likelihood_field": dict(weighting="likelihood_field"),
    "beam_model": dict(weighting="beam_model"),
}
DEFAULT_VARIANT = next(
    (name for name, v in VARIANTS.items() if all(getattr(MCLConfig, k) == value for k, value in v.items())), None
)


def simulator_nog(resolution_m: float = 0.05, device: str = "cpu") -> NOG:
    cfg = compose_config(["sim.duration_s=1"])
    _, world = simulate(cfg.sim, device)
    lo = world.segments.reshape(-1, 2).min(0) - 1.0
    hi = world.segments.reshape(-1, 2).max(0) + 1.0
    shape = tuple(np.ceil((hi - lo) / resolution_m).astype(int)[::-1])
    walls = SIM.build("rasterize", device=device)(world.segments, tuple(lo), resolution_m, shape) > 0
    return NOG(
        walls.astype(np.float32), (float(lo[0] + resolution_m / 2), float(lo[1] + resolution_m / 2)), resolution_m
    )


def _sync(device: str) -> None:
    wp.synchronize_device(device)
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def host_profile(fn, sync, steps: int, what: str) -> None:
    """Where a step's host time goes: cProfile over ``steps`` calls, the 12 largest own times."""
    import cProfile
    import io
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    for _ in range(steps):
        fn()
    sync()
    prof.disable()
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("tottime").print_stats(12)
    print(f"host profile ({what}, {steps} steps):\n" + "\n".join(text.getvalue().splitlines()[4:24]))


def device_profile(fn, steps: int, what: str) -> dict:
    """Where a step's GPU time goes: the CUDA kernels and copies of ``steps`` calls as CUPTI records them
    (torch.profiler; a captured graph's kernels are recorded one by one), per step: each kernel's time, their
    sum, and the wall time. The gap between the two is launch latency and the host."""
    from torch.profiler import ProfilerActivity, profile

    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CUDA, ProfilerActivity.CPU]) as prof:
        t0 = time.perf_counter()
        for _ in range(steps):
            fn()
        torch.cuda.synchronize()
        wall = (time.perf_counter() - t0) / steps
    kernels = {}
    for e in prof.events():
        if e.device_type.name == "CUDA":
            kernels.setdefault(e.name[:60], []).append(
                e.device_time_total if hasattr(e, "device_time_total") else e.cuda_time_total
            )
    per_step = {k: sum(v) / steps / 1e3 for k, v in kernels.items()}  # us -> ms
    busy = sum(per_step.values())
    print(
        f"device profile ({what}, {steps} steps): wall {1e3 * wall:.3f} ms per step, kernels and copies "
        f"{busy:.3f} ms, {sum(len(v) for v in kernels.values()) / steps:.0f} per step"
    )
    for k, ms in sorted(per_step.items(), key=lambda kv: -kv[1])[:14]:
        print(f"  {ms * 1e3:8.1f} us  x{len(kernels[k]) / steps:.0f}  {k}")
    return {
        "wall_ms": 1e3 * wall,
        "device_ms": busy,
        "per_step_us": {k: 1e3 * v for k, v in per_step.items()},
        "launches_per_step": sum(len(v) for v in kernels.values()) / steps,
    }


def host_split(pf, u, measured, sync, steps: int, repeats: int) -> dict:
    """Where a full step's wall time goes (ms per call, median of ``repeats`` timings of ``steps`` calls): the step;
    its captured graph replayed and waited for; replayed back to back with one wait at the end (the device's own
    time per step); the step's upload and its read-back alone (host); a wait with nothing in flight. The step less the
    graph's replay and wait is the host's part. Needs a captured step (``pf.use_graph``, after a step); the filter's
    draws and step count move on (a benchmark's filter, not a run's)."""
    graph = pf.graphs.get(pf.particles.ptr)
    if graph is None:
        return {}
    limit = pf.cfg.resample_threshold * pf.num_particles
    calls = {
        "step": lambda: pf.step(u, measured),
        "replay and wait": lambda: (wp.capture_launch(graph), sync()),
        "replay back to back": lambda: wp.capture_launch(graph),
        "upload": lambda: pf._upload(u, measured),
        "read back": lambda: pf._read_estimate(limit, 0.0),
        "wait alone": sync,
    }
    out = {}
    for name, fn in calls.items():
        if name == "step":  # (the next step's graph is the other ping-pong buffer's: both are captured after two)
            fn()
            graph = pf.graphs.get(pf.particles.ptr, graph)
        t = repeated(fn, sync, steps, repeats)
        out[name] = {"ms": 1e3 * t["median"], "min": 1e3 * t["min"], "max": 1e3 * t["max"]}
    return out


def bench_filter(
    nog,
    variant,
    n,
    device,
    steps,
    far_m,
    angles,
    measured,
    seed=0,
    repeats=5,
    graph="on",
    profile=False,
    around=None,
    cuda_trace=False,
    split=False,
) -> dict:
    cfg = MCLConfig(num_particles=n, resample_threshold=1.0, seed=seed, step_graph=graph, **VARIANTS[variant])
    free = NOG(np.where(nog.occupancy < 0.1, 0.0, 1.0).astype(np.float32), nog.origin_xy, nog.resolution_m)
    half = nog.resolution_m / 2  # the grid models read the NOG's nodes as cell centres
    maps = WeightingMaps(
        nog=nog,
        occupancy=nog.occupancy,
        resolution_m=nog.resolution_m,
        origin_xy=(nog.origin_xy[0] - half, nog.origin_xy[1] - half),
    )
    cached = None
    if cfg.weighting == "nog_table":  # was its table on disk already (irmcl_warp/services/table_cache.py)?
        kept = table_cache.table_path(nog, nog_table_settings(cfg, far_m), pick_device(device))
        cached = kept is not None and kept.is_file()
    started = time.perf_counter()
    pf = build_filter(cfg, free, (0.0, 0.0, 0.0), angles, far_m, device, maps)
    _sync(device)
    build_s = time.perf_counter() - started
    if around is None:
        pf.init_uniform()
    else:  # a converged filter: a Gaussian around the pose the scan was taken from (pose, std)
        pf.init_gaussian(*around)
    u = (0.01, 0.05, -0.01)
    sync = lambda: _sync(device)  # noqa: E731
    step = repeated(lambda: pf.step(u, measured), sync, steps, repeats)  # median and spread of ``repeats``
    if profile:
        host_profile(lambda: pf.step(u, measured), sync, steps, f"{variant}, {n:,} particles, graph {pf.use_graph}")
    host = host_split(pf, u, measured, sync, steps, repeats) if split and pf.use_graph else None
    trace = None
    if cuda_trace and device.startswith("cuda"):
        trace = device_profile(lambda: pf.step(u, measured), steps, f"{variant}, {n:,} particles, graph {pf.use_graph}")
    blocks = getattr(pf.weighting, "blocks", pf.motion.blocks)
    split = 1 if pf.use_graph else blocks.blocks_for(n)  # a captured step is one launch per part
    parts = {  # each part alone, on the same particles (the sum differs from the step by launch overlap)
        "motion": lambda: pf.motion(pf.particles, u, seed=1),
        "weighting": lambda: pf.weighting(pf.particles, pf.T_base_laser, pf.angles, pf.measured, pf.log_lik),
        "weights": lambda: pf.weights.update(pf.log_w, pf.particles),
        "estimate": lambda: pf.estimator.launch(pf.particles, pf.log_w),
        "resample": lambda: pf.resampler(pf.weights.cdf, pf.particles, pf.scratch, 0.5),
        "read back": lambda: pf.weights.summary(),
    }
    part_ms = {name: 1e3 * time_per_call(fn, sync, steps, warmup=0) for name, fn in parts.items()}
    row = {
        "method": f"{variant} {'graph' if pf.use_graph else 'eager'}" + (f" {split} blocks" if split > 1 else ""),
        "cpu_blocks": split,  # the weighting's (else the motion's) particles split over this many CPU cores
        "variant": variant,
        "graph": pf.use_graph,
        "particles": n,
        **step_ms_fields(step),
        "weighting_ms": part_ms["weighting"],
        "parts_ms": part_ms,
        "build_s": build_s,
        "table_from_cache": cached,
    }
    if trace is not None:
        row["device_profile"] = trace
    if host:
        row["host_split_ms"] = host
    if cfg.weighting == "nog_table":
        row["table_vs_march_m"] = table_error(pf, nog, cfg, far_m, device)
    return row


def table_error(pf, nog, cfg, far_m, device) -> dict:
    """|table range - march range| over the filter's particles and beams where both see a wall: median, 90th
    percentile, maximum (m)."""
    march = WEIGHTING.build(
        "nog_raymarch",
        nog=nog,
        num_particles=pf.num_particles,
        num_beams=len(pf.beam_index),
        num_samples=cfg.num_samples,
        near_m=cfg.near_m,
        far_m=far_m,
        t_min=cfg.t_min,
        device=device,
    )
    want = march.render(pf.particles, pf.T_base_laser, pf.angles).numpy()
    got = pf.weighting.render(pf.particles, pf.T_base_laser, pf.angles).numpy()
    both = (want > 0) & (got > 0)
    off = np.abs(got - want)[both]
    if (
        not off.size
    ):  # no ray hits a wall in both (e.g. many --steps of the bench's odometry drove the cloud off the map)
        return {"median": None, "p90": None, "max": None, "rays": 0}
    return {
        "median": float(np.median(off)),
        "p90": float(np.quantile(off, 0.9)),
        "max": float(off.max()),
        "rays": int(both.sum()),
    }


def bench_torch(nog, n, device, steps, far_m, angles, measured, seed=0) -> dict:
    dev = torch.device("cuda" if device.startswith("cuda") else "cpu")
    rng = np.random.default_rng(seed)
    free = np.argwhere(nog.occupancy < 0.1)[:, ::-1] * nog.resolution_m + np.asarray(nog.origin_xy)
    k = rng.integers(0, len(free), n)
    particles = torch.tensor(np.column_stack([free[k], rng.uniform(-np.pi, np.pi, n)]), dtype=torch.float32, device=dev)
    grid = torch.tensor(nog.occupancy, device=dev)
    beams = np.unique(np.linspace(0, len(angles) - 1, 32).round().astype(int))
    a = torch.tensor(angles[beams], device=dev)
    m = torch.tensor(measured[beams], device=dev)

    def once():
        return nog_log_weights_torch(
            grid, nog.origin_xy, nog.resolution_m, particles, (0.0, 0.0, 0.0), a, m, 256, 0.02, far_m, 0.5, chunk=500
        )

    with torch.no_grad():
        s = time_per_call(once, lambda: _sync(device), steps, warmup=1)
    return {"method": "torch (authors' formulation)", "particles": n, "step_ms": None, "weighting_ms": 1e3 * s}


def measured_scan(nog, far_m, device, seed=0, with_pose=False):
    """360 beams rendered from a free pose on the NOG, plus 2 cm noise."""
    rng = np.random.default_rng(seed)
    free = np.argwhere(nog.occupancy < 0.1)[:, ::-1] * nog.resolution_m + np.asarray(nog.origin_xy)
    pose = np.append(free[rng.integers(len(free))], rng.uniform(-np.pi, np.pi)).astype(np.float32)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 360).astype(np.float32)
    w = WEIGHTING.build("nog_raymarch", nog=nog, num_particles=1, num_beams=360, far_m=far_m, device=device)
    r = w.render(
        wp.array(pose[None], dtype=wp.vec3, device=w.device),
        (0, 0, 0),
        wp.array(angles, dtype=wp.float32, device=w.device),
    ).numpy()[0]
    r = r + rng.normal(0, 0.02, r.shape)
    scan = np.where((r > 0.05) & (r < far_m - 0.5), r, np.nan).astype(np.float32)
    return (angles, scan, pose) if with_pose else (angles, scan)


def run_mcl_bench(a) -> list[dict]:
    device = pick_device(a.device or "auto")
    nog = NOG.load(Path(a.nog)) if a.nog else simulator_nog(device=device)
    far_m = a.far_m
    angles, measured, pose = measured_scan(nog, far_m, device, with_pose=True)
    around = (pose, tuple(a.around)) if a.around else None
    rows = []
    for n in a.particles:
        for v in a.variants:
            for graph in ["on", "off"] if a.step_graph == "both" else [a.step_graph]:
                rows.append(
                    bench_filter(
                        nog,
                        v,
                        n,
                        device,
                        a.steps,
                        far_m,
                        angles,
                        measured,
                        repeats=a.repeats,
                        graph=graph,
                        profile=a.profile,
                        around=around,
                        cuda_trace=a.cuda_trace,
                        split=a.host_split,
                    )
                )
                print(rows[-1], flush=True)
        if n <= a.torch_max:
            rows.append(bench_torch(nog, n, device, max(1, a.steps // 4), far_m, angles, measured))
            print(rows[-1], flush=True)
            ref = rows[-1]["weighting_ms"]
            for r in rows:
                if r["particles"] == n and r["step_ms"] is not None:
                    r["speedup_vs_torch"] = ref / r["step_ms"]
    name = torch.cuda.get_device_name() if device.startswith("cuda") else platform.processor() or "cpu"
    src = a.nog or "simulator walls (5 cm)"
    print(f"\nMCL step on {name} ({device}), NOG {src} {nog.shape}, 32 beams x 256 samples, far {far_m} m")
    print(
        "| method | particles | full step (ms): median of repeats [min-max] | weighting (ms) | x faster than torch "
        "(full step vs its weighting) |"
    )
    print("|---|---|---|---|---|")
    for r in rows:
        step = (
            f"{r['step_ms']:.3f} [{r['step_ms_min']:.3f}-{r['step_ms_max']:.3f}]" if r["step_ms"] is not None else "-"
        )
        sp = f"{r['speedup_vs_torch']:.0f}" if "speedup_vs_torch" in r else "-"
        print(f"| {r['method']} | {r['particles']:,} | {step} | {r['weighting_ms']:.3f} | {sp} |")
    for r in rows:
        if "table_vs_march_m" in r:
            e = r["table_vs_march_m"]
            how = "read from the disk cache" if r.get("table_from_cache") else "built"
            if not e["rays"]:
                print(f"{r['method']} {r['particles']:,}: table {how} in {r['build_s']:.2f} s; no ray hits a wall")
                continue
            print(
                f"{r['method']} {r['particles']:,}: table {how} in {r['build_s']:.2f} s; |table - march| median "
                f"{e['median']:.4f} m, 90th percentile {e['p90']:.4f} m, max {e['max']:.2f} m over {e['rays']:,} rays"
            )
    for r in rows:
        if "host_split_ms" in r:
            parts = ", ".join(f"{k} {v['ms']:.4f}" for k, v in r["host_split_ms"].items())
            print(f"{r['method']} {r['particles']:,}, where a step's time goes (ms, median): {parts}")
    print(
        "\nparts of a step alone (ms): "
        + ", ".join(
            f"{r['method']} {r['particles']:,}: " + " ".join(f"{k} {v:.3f}" for k, v in r["parts_ms"].items())
            for r in rows
            if "parts_ms" in r
        )
    )
    out = record_path(a.out, "mcl", device)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(
        out,
        {
            "device": device,
            "device_name": name,
            "nog": src,
            "nog_shape": list(nog.shape),
            "far_m": far_m,
            "particles_start": "uniform over the free cells"
            if around is None
            else f"Gaussian around the scan's pose, std {list(a.around)}",
            "argv": vars(a),
            "rows": rows,
        },
    )
    print(f"-> {out}")
    return rows


def add_parser(sub) -> None:
    p = sub.add_parser("mcl", help="ms per MCL step (Warp variants) vs the authors' torch NOG weighting")
    p.add_argument("--device", default=None)
    p.add_argument("--particles", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--torch-max", type=int, default=1_000_000, help="largest particle count for the torch reference")
    p.add_argument(
        "--step-graph",
        default="both",
        choices=["both", "on", "off"],
        help="a step replayed as one captured graph (on), launched one by one (off), or both side by side",
    )
    p.add_argument("--profile", action="store_true", help="also print where the host time of a step goes (cProfile)")
    p.add_argument(
        "--cuda-trace",
        action="store_true",
        help="also list the CUDA kernels of a step with their device times (torch.profiler / CUPTI)",
    )
    p.add_argument(
        "--host-split",
        action="store_true",
        help="also time the step's parts apart (graph replayed and waited for, back to back, upload, read-back, a bare "
        "wait): how much of a step is the host's",
    )
    p.add_argument("--nog", default=None, help="a baked NOG (.npz); default: the simulator's walls")
    p.add_argument("--far", dest="far_m", type=float, default=40.0, help="the far bound (m)")
    p.add_argument(
        "--around",
        type=float,
        nargs=3,
        metavar=("SX", "SY", "SYAW"),
        help="start the particles as a Gaussian (std in m, m, rad) around the pose the scan was taken from, "
        "as a converged filter holds them, instead of uniform over the free cells",
    )
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--repeats", type=int, default=5, help="timings of --steps steps each; the table shows their median")
    p.add_argument("--out", default="outputs/bench")
