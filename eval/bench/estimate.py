"""``python -m eval.bench estimate``: IR-MCL's top-share estimate alone (``TopShareMean``: the top 80 % of the
particles by weight, then their weighted mean), by Warp's radix sort against the radix select (``select``: as many
particles a thread as ``select_per_thread`` chooses; ``select<P>``: P), side by side in one run. Each way is timed as the filter runs it (the keys written, then
``order`` and ``sum`` from the weights w), captured once as a CUDA graph on a GPU and replayed. Two weight sets:
``spread`` (log-weights as a scan's sum of beam log-likelihoods gives them: normal, sd 5) and ``ties`` (a resampled
set: every value shared by about ten particles). Every way must give the same top share: the estimate of each is
checked against the sort's (the sums' last bits may differ: another order of adding).

Prints a table (median of ``--repeats`` timings of ``--steps`` calls, ms per estimate) and writes
``<out>/estimate-<device>.json``. Absolute times count only from a GPU."""

from __future__ import annotations

import platform

import numpy as np
import warp as wp

from eval.bench.timing import record_path, repeated, step_ms_fields
from irmcl_warp.kernels import ESTIMATE, init_warp, pick_device
from irmcl_warp.kernels.estimate import TopShareMean
from irmcl_warp.services.outputs import write_json


def weight_set(kind: str, n: int, rng) -> np.ndarray:
    """Log-weights of ``kind`` (``spread`` or ``ties``) for n particles."""
    if kind == "spread":
        return rng.normal(-50.0, 5.0, n).astype(np.float32)
    values = rng.normal(-50.0, 5.0, max(1, n // 10)).astype(np.float32)
    return values[rng.integers(0, len(values), n)]


def method_settings(method: str) -> dict:
    """``sort``, ``select`` (the particles a thread by ``select_per_thread``) or ``select<P>`` (P particles a thread)
    as TopShareMean's class settings."""
    if method == "sort":
        return {"SELECT": False, "TILED": None}
    if method == "select":
        return {"SELECT": True, "SELECT_PER_THREAD": None}
    if method.startswith("select") and method[6:].isdigit():
        return {"SELECT": True, "SELECT_PER_THREAD": int(method[6:])}
    raise ValueError(f"eval.bench estimate: unknown method {method!r}: sort or select<particles a thread>")


def build(method: str, n: int, device: str) -> TopShareMean:
    saved = {k: getattr(TopShareMean, k) for k in ("SELECT", "TILED", "SELECT_PER_THREAD")}
    try:
        for k, v in method_settings(method).items():
            setattr(TopShareMean, k, v)
        return ESTIMATE.build("top_share", num_particles=n, share=0.8, device=device)
    finally:
        for k, v in saved.items():
            setattr(TopShareMean, k, v)


def bench_one(method: str, kind: str, n: int, device: str, steps: int, repeats: int) -> dict:
    rng = np.random.default_rng(n)
    log_w = weight_set(kind, n, rng)
    particles = np.stack([rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), rng.uniform(-np.pi, np.pi, n)], -1)
    pw = wp.array(particles.astype(np.float32), dtype=wp.vec3, device=device)
    lw = wp.array(log_w, dtype=wp.float32, device=device)
    w = wp.array(np.exp(log_w - log_w.max()).astype(np.float32), dtype=wp.float32, device=device)
    est = build(method, n, device)
    est.rank(lw)  # the keys, as the filter's accumulate launch writes them

    def once():
        est.order()
        est.sum(pw, lw, w)

    fn = once
    if wp.get_device(device).is_cuda:
        once()  # compiled and loaded before the capture
        with wp.ScopedCapture(device=device) as capture:
            once()
        fn = lambda: wp.capture_launch(capture.graph)  # noqa: E731
    timing = repeated(fn, lambda: wp.synchronize_device(device), steps, repeats)
    return {"method": method, "weights": kind, "particles": n, **step_ms_fields(timing), "pose": est.result().tolist()}


def run_estimate_bench(a) -> list[dict]:
    init_warp()
    device = pick_device(a.device or "auto")
    rows = []
    for n in a.particles:
        for kind in a.weights:
            for method in a.methods:
                rows.append(bench_one(method, kind, n, device, a.steps, a.repeats))
                x = rows[-1]
                print(f"{method} {kind} {n}: {x['step_ms']:.4f} ms", flush=True)
    for x in rows:  # every way's estimate against the first way's on the same set
        first = next(r for r in rows if r["particles"] == x["particles"] and r["weights"] == x["weights"])
        d = np.asarray(x["pose"]) - np.asarray(first["pose"])
        x["pose_diff_vs_first"] = [float(abs(d[0])), float(abs(d[1])), float(abs(np.angle(np.exp(1j * d[2]))))]
    dev = wp.get_device(device)
    name = dev.name if dev.is_cuda else platform.processor() or "cpu"
    print(f"\nThe top-share estimate alone on {name} ({device}), Warp {wp.config.version}, share 0.8")
    print(
        f"| particles | weights | method | ms per estimate: median of {a.repeats} [min-max] | "
        f"pose vs {a.methods[0]} (m, m, rad) |\n|---|---|---|---|---|"
    )
    for x in rows:
        diff = ", ".join(f"{v:.1e}" for v in x["pose_diff_vs_first"])
        print(
            f"| {x['particles']:,} | {x['weights']} | {x['method']} | {x['step_ms']:.4f} "
            f"[{x['step_ms_min']:.4f}-{x['step_ms_max']:.4f}] | {diff} |"
        )
    out = record_path(a.out, "estimate", device)
    write_json(out, {"device": device, "device_name": name, "warp": wp.config.version, "argv": vars(a), "rows": rows})
    print(f"-> {out}")
    return rows


def add_parser(sub) -> None:
    t = sub.add_parser("estimate", help="the top-share estimate alone: the sort against the radix select")
    t.add_argument("--device", default=None)
    t.add_argument("--particles", type=int, nargs="+", default=[100_000, 1_000_000])
    t.add_argument("--weights", nargs="+", default=["spread", "ties"], choices=["spread", "ties"])
    t.add_argument("--methods", nargs="+", default=["sort", "select", "select1", "select4", "select8"])
    t.add_argument("--steps", type=int, default=50)
    t.add_argument("--repeats", type=int, default=5)
    t.add_argument("--out", default="outputs/bench")
