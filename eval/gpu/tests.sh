#!/usr/bin/env bash
# The GPU test run (docs/benchmarks.md, "GPU tests"): on the lent GPU, after the packages are unpacked
# (../shared/tools/gpu/README.md). The kernel tests run on cuda:0 against the same CPU twins
# (tests/devices.py), then the CUDA-only checks of tests/test_gpu.py (marker gpu: CUDA vs CPU parity of
# whole steps, the SLAM replay check, a short training run). The CPU compiler is not carried there, so
# tests that need a CPU kernel are deselected (-m "not data and not cpu_only").
set -uo pipefail
export IRMCL_TEST_DEVICE=cuda:0 PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
python -c "import warp as wp; wp.init(); print('warp', wp.config.version, wp.get_cuda_devices())"
python -m pytest -q -p no:cacheprovider -m "not data and not slow and not cpu_only" --timeout 300 \
  tests/test_render.py tests/test_weighting.py tests/test_particles.py tests/test_raycast.py tests/test_mapping.py \
  tests/test_sim.py tests/test_slam.py tests/test_mcl.py tests/test_worlds.py tests/test_online.py tests/test_table_cache.py \
  tests/test_extend.py 2>&1 | tee "${OUT:-.}/gpu-kernel-tests.log" | tail -25
python -m pytest -q -p no:cacheprovider -m gpu --timeout 300 tests/test_gpu.py 2>&1 | tee "${OUT:-.}/gpu-tests.log" | tail -25
# the MCL step with the filter factory (one filter for every user), 5 repeats per size
python -m eval.bench mcl --out "${OUT:-.}" --repeats 5 2>&1 | tail -16
