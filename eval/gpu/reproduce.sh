#!/usr/bin/env bash
# Wall time of `python -m eval.reproduce` for a set of sweeps on this GPU host, with one GPU and with every GPU
# (the pool launcher: CUDA_VISIBLE_DEVICES per job), each in a fresh working folder so that nothing is found
# done, kept runs run again (--rerun-kept). A first job compiles the Warp kernels into the shared kernel cache
# so that neither measurement pays for it. After the packages are unpacked (../shared/tools/gpu/README.md) and
# the logs staged (eval/gpu/stage_data.sh):
#   SWEEPS="--only slam --match +exp=gmapping_fr079" RUNS="1:4 2:4 1:8" bash eval/gpu/reproduce.sh
# Env: SWEEPS (eval.reproduce's selection), RUNS (what to time, each <GPUs>:<jobs sharing one GPU>; default
# "1:8 <all>:8"), WARM (overrides of the warm-up job). Results: $OUT/reproduce-<GPUs>gpu-<jobs>.json and .log.
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-.}
export PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
all=$(nvidia-smi -L | grep -c '^GPU ')
warm=$(mktemp -d)
start=$(date +%s)
(cd "$warm" && python -m irmcl_warp.slam ${WARM:-+exp=gmapping_fr079 slam.seed=99} device=cuda:0 2>&1 | tail -2)
echo "warm-up (kernel compile and one run): $(( $(date +%s) - start )) s"
for run in ${RUNS:-1:8 $all:8}; do
  g=${run%:*}; per=${run#*:}; name="reproduce-${g}gpu-${per}"
  work=$(mktemp -d)
  python -m eval.reproduce ${SWEEPS:?which sweeps} --rerun-kept --no-tables --gpus "$g" --jobs-per-gpu "$per" \
    --workdir "$work" --report "$OUT/$name.json" > "$OUT/$name.log" 2>&1
  echo "$g GPU(s), $per job(s) each: exit $?; $(grep '^reproduce:' "$OUT/$name.log")"
  grep -c manifest.json <(find "$work/outputs" -name manifest.json) | sed 's/^/  finished runs: /'
done
