"""The top-share estimate's sort and sums on a second CUDA stream (an experiment, not the filter's code: twenty-first
session, docs/benchmarks.md). ``FORK=1 python eval/gpu/second_stream.py localize <hydra args>`` or ``... bench <eval.bench
mcl args>`` runs the stage or the benchmark with ParticleFilter's ``_normalise`` / ``_copy_sums`` forking the estimate onto
a second stream beside the weights' sums, the scan and the resampling (joined before the read-back); ``FORK=0`` runs
them as they are. With the ordered scan the forked runs repeat themselves and the one-stream run's bits; it is not
the filter's default because its final form was not tested on a GPU in that session."""

import os
import runpy
import sys

import warp as wp

from irmcl_warp.mcl.filter import ParticleFilter


def _fork(self) -> bool:
    if not (self.weights.tiled and wp.get_device(self.device).is_cuda and hasattr(self.estimator, "rank_buffers")):
        return False
    if getattr(self, "_side", None) is None:
        self._side = wp.Stream(self.device)
        self._ranked, self._weighed = wp.Event(self.device), wp.Event(self.device)
    return True


def _normalise(self) -> None:
    weights, estimator, fork = self.weights, self.estimator, self._fork()
    weights.accumulate(self.log_w, self.log_lik, float(self.cfg.temper), estimator.rank_buffers() if fork else None)
    if fork:
        self._side.wait_event(wp.get_stream(self.device).record_event(self._ranked))
        with wp.ScopedStream(self._side, sync_enter=False):
            estimator.sort()
    weights.weigh(self.log_w, self.particles)
    if fork:
        self._side.wait_event(wp.get_stream(self.device).record_event(self._weighed))
        with wp.ScopedStream(self._side, sync_enter=False):
            estimator.sum(self.particles, self.log_w, weights.w)
    weights.cumulate()
    if estimator is not None and not fork:
        estimator.launch(self.particles, self.log_w)


_one_stream_copy = ParticleFilter._copy_sums


def _copy_sums(self) -> None:
    """The estimate's stream joined before the filter's own read-back copies."""
    if self._fork():
        wp.get_stream(self.device).wait_stream(self._side)
    _one_stream_copy(self)


if os.environ.get("FORK") == "1":
    ParticleFilter._fork, ParticleFilter._normalise, ParticleFilter._copy_sums = _fork, _normalise, _copy_sums
what, sys.argv = sys.argv[1], [sys.argv[1]] + sys.argv[2:]
if what == "localize":
    runpy.run_module("irmcl_warp.localize", run_name="__main__")
else:
    from eval.bench.__main__ import main

    main(["mcl", *sys.argv[1:]])
