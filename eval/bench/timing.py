"""Timing shared by the benchmarks: seconds per call after warm-up, the device synchronised around; and where a
benchmark's record goes (``record_path``: ``<kind>[-<detail>]-<device>.json``, the name results/bench/ keeps
one current record of per kind and device)."""

from __future__ import annotations

import time
from pathlib import Path


def record_path(out, kind: str, device: str, *detail: str) -> Path:
    """``out/<kind>[-<detail>...]-<device kind>.json`` (``cuda:0`` -> ``cuda``)."""
    return Path(out) / ("-".join([kind, *detail, str(device).split(":")[0]]) + ".json")


def time_per_call(fn, sync, steps: int, warmup: int = 2) -> float:
    """Seconds per call of ``fn`` over ``steps`` calls after ``warmup`` ones; ``sync()`` waits for the device."""
    for _ in range(warmup):
        fn()
    sync()
    t0 = time.perf_counter()
    for _ in range(steps):
        fn()
    sync()
    return (time.perf_counter() - t0) / steps


def repeated(fn, sync, steps: int, repeats: int, warmup: int = 2) -> dict:
    """Seconds per call over ``repeats`` separate timings of ``steps`` calls each: median, min, max, all."""
    import statistics

    times = [time_per_call(fn, sync, steps, warmup if r == 0 else 0) for r in range(repeats)]
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "all": times}


def step_ms_fields(r: dict) -> dict:
    """A ``repeated`` result as the benchmarks' records write it: ms per call, median, min, max and every repeat."""
    return {
        "step_ms": 1e3 * r["median"],
        "step_ms_min": 1e3 * r["min"],
        "step_ms_max": 1e3 * r["max"],
        "step_ms_all": [1e3 * t for t in r["all"]],
        "repeats": len(r["all"]),
    }
