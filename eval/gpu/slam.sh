#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# One GPU session of GMapping runs (docs/benchmarks.md): per experiment a Hydra multirun over seeds and
# proposals, then the metrics, N_eff traces and maps packed into $OUT/slam-results.tgz.
# Env: EXPS (default "gmapping_intel gmapping_fr079 gmapping_mit_csail"), SEEDS (0,...,9), PROPOSALS
# (paper,gmapping_code), PARTICLES (30), EXTRA (more overrides). Data: the stream caches and the relations
# files staged by hand (IRMCL_DATA pointing at the relations).
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
EXPS=${EXPS:-"gmapping_intel gmapping_fr079 gmapping_mit_csail"}
for exp in $EXPS; do
  echo "=== $exp"
  python -m irmcl_warp.slam -m +exp="$exp" slam.seed="${SEEDS:-0,1,2,3,4,5,6,7,8,9}" \
    slam.proposal="${PROPOSALS:-paper,gmapping_code}" slam.num_particles="${PARTICLES:-30}" ${EXTRA:-} 2>&1 \
    | grep -E "scans processed|Error|error" | grep -v "^\["
done
find outputs -path "*/slam/*" -not -path "*/.*" \( -name metrics.json -o -name config.yaml -o -name manifest.json -o -name neff.csv \
  -o -name map.png -o -name trajectory.tum \) > "$OUT/files.txt"
tar czf "$OUT/slam-results.tgz" -T "$OUT/files.txt"
ls -la "$OUT"
