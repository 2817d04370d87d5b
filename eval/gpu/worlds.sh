#!/usr/bin/env bash
# Issue 33 on the lent GPU (after the packages are unpacked: ../shared/tools/gpu/README.md). Usage: bash eval/gpu/worlds.sh <part>
#   runs    the worlds stage on the test split with the GPU's 100k particles (conf/exp/worlds.yaml: the likelihood
#           field as tuned on the tuning worlds, the shipped calibration), then kidnapped runs (30 s in, 5 per world)
#   tests   the tests this change touched, kernels on cuda:0 (IRMCL_TEST_DEVICE)
# Results: $OUT/worlds-results.tgz (outputs/worlds/worlds/<run>/); back here, unpack it into the repository root.
set -uo pipefail
export PYTHONUNBUFFERED=1 TQDM_DISABLE=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
case "${1:-runs}" in
  runs)
    # the features depend on the particle count (a 100k cloud keeps a wider spread): calibrate at 100k on the tuning worlds
    python -m irmcl_warp.worlds +exp=worlds worlds.split=tuning worlds.runs=3 mcl.num_particles=100000 device=cuda:0 2>&1 | tail -1
    python -m eval.confidence fit outputs/worlds/worlds/tuning-likelihood_field-100k-* --out results/worlds/calibration-likelihood_field-100k.json
    cal=$PWD/results/worlds/calibration-likelihood_field-100k.json
    python -m irmcl_warp.worlds +exp=worlds worlds.split=test mcl.num_particles=100000 worlds.calibration=$cal device=cuda:0 2>&1 | tail -1
    python -m irmcl_warp.worlds +exp=worlds worlds.split=test mcl.num_particles=100000 worlds.kidnap_at_s=30 \
      worlds.runs=5 worlds.calibration=$cal device=cuda:0 2>&1 | tail -1
    tar czf "${OUT:-.}/worlds-results.tgz" outputs/worlds/worlds results/worlds ;;
  tests)
    IRMCL_TEST_DEVICE=cuda:0 python -m pytest -q -p no:cacheprovider -m "not data and not slow and not cpu_only" \
      --timeout 300 tests/test_worlds.py tests/test_weighting.py tests/test_particles.py tests/test_mcl.py 2>&1 \
      | tee "${OUT:-.}/gpu-worlds-tests.log" | tail -8 ;;
esac
