#!/usr/bin/env bash
# The GPU step before and after a change, on the lent GPU (docs/benchmarks.md, twenty-first session), after the
# packages are unpacked (../shared/tools/gpu/README.md) and with IRMCL_DATA set. BEFORE: an unpacked tree of the
# commit before (git archive <commit> | tar x -C <dir>). PHASES (default all, in this order):
#   tests  the kernel and filter tests on cuda:0 and the -m gpu checks on this tree;
#   bench  the step benchmark of both trees alternately (ROUNDS rounds, PARTICLES, VARIANTS);
#   trace  one more benchmark of each tree with the device trace, the host profile and, where its bench has it
#          (--host-split), the host split (TRACE_VARIANTS, 100k);
#   g100k  a 100k global run on fr079 hashed, once before and twice after (does each repeat the other?);
#   bits   eval.same_bits of both trees (BITS_ONLY: its groups, default all) and their comparison.
# Everything lands in $OUT/step.tgz (the machine returns only a few files).
set -uo pipefail
: "${BEFORE:?an unpacked tree of the commit before}"
OUT=${OUT:-gpu-out}; ROUNDS=${ROUNDS:-2}; ROOT=$PWD; W=$(mktemp -d)
PHASES=${PHASES:-tests bench trace g100k bits}; PARTICLES=${PARTICLES:-100000 1000000}
VARIANTS=${VARIANTS:-warp+et+beam table likelihood_field}; TRACE_VARIANTS=${TRACE_VARIANTS:-table likelihood_field}
mkdir -p "$OUT"; export TQDM_DISABLE=1
has() { case " $PHASES " in *" $1 "*) return 0;; *) return 1;; esac; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$W/device.txt"
tree() { if [ "$1" = before ]; then echo "$BEFORE"; else echo "$ROOT"; fi; }
if has tests; then
  IRMCL_TEST_DEVICE=cuda:0 timeout 240 python -m pytest -q -p no:cacheprovider -m "not data and not slow and not cpu_only" \
    --timeout 300 tests/test_particles.py tests/test_mcl.py tests/test_worlds.py tests/test_online.py tests/test_weighting.py \
    2>&1 | tee "$W/gpu-kernel-tests.log" | tail -2
  timeout 150 python -m pytest -q -p no:cacheprovider -m gpu --timeout 300 tests/test_gpu.py 2>&1 | tee "$W/gpu-tests.log" | tail -2
fi
if has bench; then
  for round in $(seq "$ROUNDS"); do
    for side in before after; do
      dir=$(tree $side)
      # shellcheck disable=SC2086
      (cd "$dir" && PYTHONPATH=/root/site:$dir timeout 150 python -m eval.bench mcl --device cuda:0 --particles $PARTICLES \
        --variants $VARIANTS --step-graph on --repeats 5 --torch-max 0 --out "$W/bench-$side-$round" \
        > "$W/bench-$side-$round.log" 2>&1; grep "graph |" "$W/bench-$side-$round.log" | sed "s/^/$side $round /")
    done
  done
fi
if has trace; then
  for side in before after; do
    dir=$(tree $side); split=""
    grep -q -- "--host-split" "$dir/eval/bench/mcl.py" && split=--host-split
    # shellcheck disable=SC2086
    (cd "$dir" && PYTHONPATH=/root/site:$dir timeout 150 python -m eval.bench mcl --device cuda:0 --particles 100000 \
      --variants $TRACE_VARIANTS --step-graph on --repeats 3 --torch-max 0 --cuda-trace --profile $split \
      --out "$W/trace-$side" > "$W/trace-$side.log" 2>&1; grep -E "device profile|graph \||time goes" "$W/trace-$side.log" | sed "s/^/$side /")
  done
fi
if has g100k; then
  for run in before:1 after:1 after:2; do
    side=${run%%:*}; k=${run##*:}; dir=$(tree $side); d=$W/g-$side-$k; mkdir -p "$d"
    (cd "$d" && PYTHONPATH=/root/site:$dir timeout 100 python -m irmcl_warp.localize +exp=fr079 mcl.weighting=likelihood_field \
      localize.mode=global localize.num_starts=2 localize.run_s=8 mcl.num_particles=100000 device=cuda:0 > "$d.log" 2>&1 \
      || tail -3 "$d.log")
    (cd "$d" && find . -name "start*.tum" | sort | xargs sha256sum | cut -c1-16 | tr '\n' ' ' | sed "s/^/g100k $side $k /"; echo) \
      | tee -a "$W/g100k.txt"
  done
fi
if has bits; then
  # shellcheck disable=SC2086
  only=${BITS_ONLY:+--only $BITS_ONLY}
  timeout 240 python -m eval.same_bits run --tree "$BEFORE" --device cuda:0 $only --out "$W/bits-before.json" 2>&1 | tail -1
  timeout 240 python -m eval.same_bits run --device cuda:0 $only --out "$W/bits-after.json" 2>&1 | tail -1
  python -m eval.same_bits compare "$W/bits-before.json" "$W/bits-after.json" 2>&1 | tail -3 | tee "$W/bits-compare.txt"
fi
rm -rf "$W"/g-*/ && tar czf "$OUT/step.tgz" -C "$W" . && ls -la "$OUT"
