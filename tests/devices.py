"""The Warp device the kernel tests run on: the CPU (CI), or the device named by ``IRMCL_TEST_DEVICE`` (on a
lent GPU: ``IRMCL_TEST_DEVICE=cuda:0 python -m pytest -m "not data" tests/test_<kernels>.py``, the same
parity tests against the same CPU twins; docs/benchmarks.md records the last such run)."""

import os

DEVICE = os.environ.get("IRMCL_TEST_DEVICE", "cpu")
