#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# One GPU session of NOF measurements (docs/benchmarks.md): the training benchmark, then train + scan
# synthesis for each experiment and preset given, copying the results to $OUT (or ./gpu-out).
# Usage: bash eval/gpu/nof.sh "<preset>:<exp> ..."   e.g. "fast:fr079 fast:intel paper:intel"
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
if [ -n "${BENCH:-}" ]; then
  python -m eval.bench train --device cuda --batch 1024 4096 --steps 20 --amp --out "$OUT/bench" 2>&1 | tail -14
fi
for job in $1; do
  preset=${job%%:*}; exp=${job#*:}
  echo "=== $exp train=$preset"
  python -m irmcl_warp.train +exp="$exp" train="$preset" ${EXTRA:-} 2>&1 | grep -v "it/s\|step/s\|s/step" | tail -8
  python -m irmcl_warp.synthesis +exp="$exp" train="$preset" ${EXTRA:-} 2>&1 | tail -1
done
# the machine may send back only a few files: pack the finished runs' records (python -m eval.keep reads them)
find outputs \( -path "*/train/*" -o -path "*/synthesis/*" \) -not -path "*/.*" \( -name metrics.json -o -name config.yaml \
  -o -name manifest.json -o -name scan.png \) > "$OUT/files.txt"
tar czf "$OUT/nof-results.tgz" -T "$OUT/files.txt"
