"""The filter's step with the top-share estimate on one stream or two, side by side (ParticleFilter.SECOND_STREAM;
twenty-first and twenty-second sessions, docs/benchmarks.md). ``FORK=0 python eval/gpu/second_stream.py localize <hydra
args>`` or ``... bench <eval.bench mcl args>`` runs the stage or the benchmark with the estimate on the filter's own
stream; ``FORK=1`` (or no FORK) as the filter does by default, on a second stream."""

import os
import runpy
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the project root: eval's modules
from irmcl_warp.mcl.filter import ParticleFilter

ParticleFilter.SECOND_STREAM = os.environ.get("FORK", "1") == "1"
what, sys.argv = sys.argv[1], [sys.argv[1]] + sys.argv[2:]
if what == "localize":
    runpy.run_module("irmcl_warp.localize", run_name="__main__")
else:
    from eval.bench.__main__ import main

    main(["mcl", *sys.argv[1:]])
