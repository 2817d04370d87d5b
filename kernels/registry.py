"""The registries (one per concern: name -> factory), Warp's start and the device choice. The kernel families
import these from here; ``kernels/__init__.py`` re-exports them and imports the families, which registers them."""

from __future__ import annotations

import os
import sys
import tempfile

import numpy as np
import warp as wp


def _quiet() -> None:
    """Warp's start-up banner and module-load lines only with IRMCL_WARP_VERBOSE=1 (Warp 1.19 reads
    ``log_level``; older releases ``quiet``)."""
    verbose = os.environ.get("IRMCL_WARP_VERBOSE", "0") == "1"
    wp.config.quiet = not verbose
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_INFO if verbose else wp.LOG_WARNING


_quiet()


class Registry:
    def __init__(self, concern: str):
        self.concern, self._factories = concern, {}

    def register(self, name: str):
        def deco(factory):
            if name in self._factories:
                raise ValueError(f"{self.concern}: {name!r} registered twice")
            self._factories[name] = factory
            return factory

        return deco

    def build(self, name: str, **settings):
        if name not in self._factories:
            raise KeyError(f"{self.concern}: unknown kernel {name!r}; choose one of {sorted(self._factories)}")
        return self._factories[name](**settings)

    def names(self) -> list[str]:
        return sorted(self._factories)


_initialised = False


NO_DRIVER_LINE = "Could not find or load the NVIDIA CUDA driver"  # what Warp's C code prints on a CPU machine


def init_warp() -> None:
    """``wp.init()``, once. Warp's C code prints a line on every machine without an NVIDIA driver; on such a
    machine that is no news (the CPU runs the kernels), so that one line is held back and any other output of
    the start-up is passed on. Asking for a CUDA device there is an error instead (``pick_device``)."""
    global _initialised
    if _initialised:
        return
    _quiet()
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        held.seek(0)
        said = held.read().decode(errors="replace").splitlines()
    rest = [line for line in said if NO_DRIVER_LINE not in line]
    if rest:
        print("\n".join(rest), file=sys.stderr)
    _initialised = True


def pick_device(requested: str = "auto") -> str:
    """``"cuda:0"`` when Warp sees a GPU, else ``"cpu"``; any explicit name (``device=cpu``) wins. A CUDA device
    asked for where Warp sees none is a ValueError (one line, not a traceback from the first launch)."""
    init_warp()
    if requested in (None, "", "auto"):
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    if str(requested).startswith("cuda") and not wp.is_cuda_available():
        raise ValueError(
            f"device={requested}: Warp sees no CUDA device on this machine (no NVIDIA driver or GPU); "
            "use device=cpu (or device=auto)"
        )
    return requested


def host_cores() -> int:
    """The cores this process may run on (its CPU affinity: in a container ``os.cpu_count()`` counts the host's)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


# The fewest particles a CPU block of the motion or a grid model gets. On the 2-core development machine (2026-11-26,
# twentieth session) a 10k-particle motion took 1.27 ms in 2 blocks against 1.56 ms in one, the likelihood field
# 2.18 against 3.04 ms, measured inside filter steps whose other launches replay as a CPU graph. (The nineteenth
# session had measured the motion alone, 2.2 ms split against 1.7 ms, and set 16k; split launches then left the step's
# graph altogether, which now keeps the rest of the step: irmcl_warp/mcl/filter.py ``_replay``.)
CPU_MIN_BLOCK = 2048


class ParticleBlocks:
    """A per-particle launch split into blocks of particles, one per CPU core, launched from as many host threads.

    Warp runs a CPU launch's threads one after another on the calling thread, and ctypes drops the GIL while a
    launch runs, so blocks launched from host threads run on separate cores. ``run(launch, n)`` calls
    ``launch(p0, p1)`` for consecutive blocks covering 0..n-1 (at least ``min_block`` particles each) and waits
    for all of them. Each particle's result comes from the same code and inputs whatever block it is in, so the
    bits do not depend on the split. On a GPU, with ``threads`` = 1, and while a graph is being captured (a CPU
    graph records the launches of the capturing thread only), it is one call of ``launch(0, n)``."""

    def __init__(self, device: str, threads: int | None = None, min_block: int = 1):
        self.device = device
        cuda = wp.get_device(device).is_cuda
        self.threads = 1 if cuda else max(1, int(threads or host_cores()))
        self.min_block = max(1, int(min_block))
        self._pool = None

    def blocks_for(self, n: int) -> int:
        """How many blocks ``run`` splits ``n`` particles into."""
        return min(self.threads, max(1, n // self.min_block))

    def run(self, launch, n: int) -> None:
        blocks = self.blocks_for(n)
        if blocks == 1 or wp.get_device(self.device).is_capturing:  # a graph captures one thread's launches
            launch(0, n)
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="particle-blocks")
        cuts = np.linspace(0, n, blocks + 1).astype(int)
        for f in [self._pool.submit(launch, int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]:
            f.result()

    def launch(self, kernel, n: int, inputs: list, per_particle: tuple[int, ...], first: int | None = None) -> None:
        """``wp.launch(kernel, n, inputs)`` run in blocks: the inputs at the positions ``per_particle`` (arrays
        indexed by particle) are sliced to each block, and the input at ``first``, if given, is set to the
        block's first particle index."""
        self.run(self.block(kernel, n, inputs, per_particle, first), n)

    def block(self, kernel, n: int, inputs: list, per_particle: tuple[int, ...], first: int | None = None):
        """The launch of ``launch`` for one block: a function (p0, p1) -> None, for ``run`` to call with others
        of the same particles (a filter runs the motion and the weighting of a block one after the other, on one
        core, in one pass: irmcl_warp/mcl/filter.py ``_move_and_observe``)."""

        def block(p0: int, p1: int) -> None:
            args = list(inputs)
            if p1 - p0 != n:
                for i in per_particle:
                    args[i] = inputs[i][p0:p1]
            if first is not None:
                args[first] = p0
            wp.launch(kernel, p1 - p0, args, device=self.device)

        return block


REDUCE_THREADS = 4096  # threads of a reduction launch up to GPU_WIDE_FROM items, and always on a CPU
REDUCE_GROUP = 64  # a GPU adds 4096 threads' partial sums in REDUCE_GROUP groups of REDUCE_GROUP (PartialSums)
# Above this many items a GPU reduction gives each thread GPU_ITEMS_PER_THREAD items (at most GPU_MAX_THREADS
# threads): with 4096 threads a 1M-particle reduction ran 244 items per thread one after another on 32 of the
# H100's 132 SMs (the weights' sums 126 us, the top-share sums 155 us of a 0.77 ms step; twelfth and twentieth
# sessions). Up to here the threads, and so the bits of every sum, are what they always were.
GPU_WIDE_FROM = 1 << 18
GPU_ITEMS_PER_THREAD = 16
GPU_MAX_THREADS = 1 << 16


def reduction_threads(n: int, device: str) -> int:
    """How many threads ``launch_reduction`` uses for n items on ``device``."""
    n = max(1, int(n))
    if n > GPU_WIDE_FROM and wp.get_device(device).is_cuda:
        return min(GPU_MAX_THREADS, -(-n // GPU_ITEMS_PER_THREAD))
    return min(n, REDUCE_THREADS)


def sums_array(given, size: int, device: str, who: str) -> wp.array:
    """Where a part writes its ``size`` float32 sums: ``given`` (a view of a filter's read-back buffer, so that one
    copy brings every part's sums back) or, when None, zeros of its own on ``device``."""
    if given is None:
        return wp.zeros(size, dtype=wp.float32, device=device)
    if given.dtype != wp.float32 or given.shape != (size,) or str(given.device) != str(wp.get_device(device)):
        raise ValueError(
            f"{who}: sums must be {size} float32 on {device}, got {given.shape} {given.dtype.__name__} on {given.device}"
        )
    return given


def launch_reduction(kernel, n: int, inputs: list, device: str) -> int:
    """Launch a reduction over n items on ``reduction_threads(n, device)`` threads and return that number; the
    kernel's last argument is the stride: thread t accumulates items t, t + stride, ... in registers and then
    writes its partial sums to row t of a ``PartialSums`` (or, for a maximum, makes one atomic max: any
    order gives the same bits). (One atomic per item on one address serialises: 8 sums over 1M particles
    cost ~20 ms on an H100, measured by eval.bench mcl.)"""
    threads = reduction_threads(n, device)
    wp.launch(kernel, threads, [*inputs, threads], device=device)
    return threads


@wp.kernel
def _sum_row_groups(partials: wp.array2d(dtype=wp.float32), rows: int, group: int, out: wp.array2d(dtype=wp.float32)):
    g, c = wp.tid()
    s = float(0.0)
    for r in range(g * group, wp.min((g + 1) * group, rows)):
        s += partials[r, c]
    out[g, c] = s


def row_groups(rows: int) -> tuple[int, int]:
    """(groups, rows per group) in which a GPU first adds ``rows`` partial sums: REDUCE_GROUP x REDUCE_GROUP up
    to REDUCE_THREADS rows (as always), else about sqrt(rows) groups of about sqrt(rows)."""
    if rows <= REDUCE_THREADS:
        return REDUCE_GROUP, REDUCE_GROUP
    size = int(np.ceil(np.sqrt(rows)))
    return -(-rows // size), size


class PartialSums:
    """C sums over many items, the same bits on every run: a reduction kernel's thread t leaves its C
    partial sums in row t of ``partials`` [threads, C], and ``finish(threads, out)`` adds the rows
    in a fixed order into ``out`` [C]. (Atomic adds from GPU threads come in a different order each run,
    and the last bits of a sum with them; resampling can turn those into different particles.)

    On the CPU the rows are added one after another: the order in which its threads used to add
    atomically, so CPU results are what they were. On a GPU, groups of rows first (one thread each;
    ``row_groups``), then the group sums; a run repeats itself, and a GPU and a CPU still differ in rounding.
    ``rows``: the most threads a reduction into it will use (``reduction_threads`` of the largest n).
    """

    def __init__(self, num_sums: int, device: str, rows: int = REDUCE_THREADS):
        self.device, self.num_sums = device, int(num_sums)
        rows = max(int(rows), REDUCE_THREADS)
        self.partials = wp.zeros((rows, self.num_sums), dtype=wp.float32, device=device)
        self.groups = wp.zeros((row_groups(rows)[0], self.num_sums), dtype=wp.float32, device=device)
        self.on_gpu = wp.get_device(device).is_cuda

    def finish(self, threads: int, out: wp.array) -> None:
        if threads > self.partials.shape[0]:
            raise ValueError(f"PartialSums: {threads} rows, room for {self.partials.shape[0]}")
        rows, total = self.partials, out.reshape((1, self.num_sums))  # the sums as one group of all rows
        if self.on_gpu:
            groups, size = row_groups(threads)
            wp.launch(
                _sum_row_groups,
                (groups, self.num_sums),
                [self.partials, threads, size, self.groups],
                device=self.device,
            )
            rows, threads = self.groups, groups
        wp.launch(_sum_row_groups, (1, self.num_sums), [rows, threads, threads, total], device=self.device)


RAYCAST = Registry("raycast")
MAPPING = Registry("mapping")
SIM = Registry("sim")
RENDER = Registry("render")
WEIGHTING = Registry("weighting")
MOTION = Registry("motion")
RESAMPLE = Registry("resample")
ESTIMATE = Registry("estimate")
SLAM = Registry("slam")
