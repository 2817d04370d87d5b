#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# One GPU session of NOF measurements (docs/benchmarks.md): the training benchmark, then train + scan
# synthesis for each experiment and preset given, copying the results to $OUT (or ./gpu-out).
# Usage: bash eval/gpu/nof.sh "<preset>:<exp> ..."   e.g. "fast:fr079 fast:intel paper:intel"
set -uo pipefail
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
if [ -n "${BENCH:-}" ]; then
  python -m eval.bench train --device cuda --batch 1024 4096 --steps 20 --amp --out "$OUT/bench" 2>&1 | tail -14
fi
for job in $1; do
  preset=${job%%:*}; exp=${job#*:}
  echo "=== $exp train=$preset"
  python -m irmcl_warp.train +exp="$exp" train="$preset" ${EXTRA:-} 2>&1 | grep -v "it/s\|step/s\|s/step" | tail -8
  python -m eval.synthesis +exp="$exp" train="$preset" ${EXTRA:-} 2>&1 | tail -1
  dest="$OUT/$exp-$preset"; mkdir -p "$dest"
  cp outputs/"$exp"/train-"$preset"/{metrics.json,config.yaml,manifest.json} "$dest/" 2>/dev/null
  cp outputs/"$exp"/synthesis-"$preset"/metrics.json "$dest/synthesis.json" 2>/dev/null
  cp outputs/"$exp"/synthesis-"$preset"/scan.png "$dest/scan.png" 2>/dev/null
done
# the machine may send back only a few files: pack them into one
tar czf "$OUT/nof-results.tgz" -C "$OUT" $(cd "$OUT" && ls -d *-*/ 2>/dev/null) && rm -rf "$OUT"/*-*/
