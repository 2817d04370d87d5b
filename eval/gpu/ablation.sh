#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# On the lent GPU, after the packages are unpacked (../shared/tools/gpu/README.md) and .gpu/e/abl.tgz is
# extracted in the repository root (the stream caches, with their split ids, and NOF checkpoints of fr079, intel and
# mit_csail, and gpudata/ with the fr079 bag and its matched corrected poses):
#   bash eval/gpu/ablation.sh loc:fr079 pipeline     # then: loc:intel loc:mit_csail, train
# Each part is a slice of `python -m eval.reproduce` (group ablation or pipeline) on cuda:0; the metrics
# come back in $OUT/gpu-results-<parts>.tgz.
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
export IRMCL_DATA=${IRMCL_DATA:-$PWD/gpudata}
run() { python -m eval.reproduce --rerun-kept --launcher basic --no-tables --hydra-arg device=cuda:0 "$@" 2>&1 \
          | grep -E "^\[|^  \\$|success|converged|Error|error|up to date|redoing|->" | grep -v "^\[W" | tail -60; }
for part in "$@"; do
  start=$(date +%s)
  case "$part" in
    loc:*) run --only ablation --match "+exp=${part#loc:}" ;;
    train) run --only ablation --match "train=fast" ;;
    pipeline) run --only pipeline --match "+exp=pipeline_fr079" ;;
    *) echo "unknown part $part" >&2 ;;
  esac
  echo "part $part: $(( $(date +%s) - start )) s"
done
find outputs \( -path "*/localize/*" -o -path "*/train/fast-*" -o -path "*/synthesis/fast-*" -o -path "*/pipeline[-_]*/pipeline/*" \
  -o -path "*/pipeline[-_]*/slam/*" \) -not -path "*/.*" -type f \( -name "*.json" -o -name "*.yaml" -o -name "*.md" -o -name "*.png" \
  -o -name "*.tum" -o -name "*.csv" \) > "$OUT/files.txt"
tar czf "$OUT/gpu-results-$(echo "$@" | tr ' :' '-_').tgz" -T "$OUT/files.txt"
ls -la "$OUT"
