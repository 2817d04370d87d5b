#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# NOF trainings on one GPU box, several processes at a time (a guided step is bound by the host, so one
# process leaves most of the GPU idle): one line of overrides per run, each naming its own train.name so
# the runs write separate folders; every run trains, then scores its field on the test scans.
#   LIST=jobs.txt JOBS=4 bash eval/gpu/nof_sweep.sh
#   e.g. a line: +exp=fr079 train=guided train.lr_schedule=cosine train.name=guided_cos train.max_time_s=null
# Runs that share the GPU are slower: their training times say nothing; time a preset alone (nof.sh).
# Env: LIST (required), JOBS (parallel processes, default 4), SWEEP_TIMEOUT (s: stop then and pack the runs
# that finished; default 540). Data: the stream caches staged beside the code. Results: $OUT/nof-sweep.tgz
# (metrics.json, config.yaml, manifest.json of every finished train and synthesis run) and $OUT/logs/<train.name>.log.
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-gpu-out}; mkdir -p "$OUT/logs"
jobs=${LIST:?LIST: a file with one line of overrides per run}
echo "$(wc -l < "$jobs") runs, ${JOBS:-4} at a time"
touch "$OUT/.sweep-start"
# Warp compiles its kernels into its cache once, not in every process at the same time
python -c "import warp as wp, kernels; wp.init(); wp.force_load('cuda:0')" > /dev/null 2>&1
start=$(date +%s)
export OUT
timeout "${SWEEP_TIMEOUT:-540}" xargs -P "${JOBS:-4}" -I{} sh -c '
  name=$(echo "{}" | sed -n "s/.*train\.name=\([^ ]*\).*/\1/p")
  { python -m irmcl_warp.train {} 2>&1 | grep -E "^epoch|best epoch|Error|error"
    python -m irmcl_warp.synthesis {} 2>&1 | tail -1; } > "$OUT/logs/$name.log"
  echo "$name: $(grep -c "^epoch" "$OUT/logs/$name.log") epochs; $(tail -1 "$OUT/logs/$name.log")"' < "$jobs"
pkill -f "python -m irmcl_warp.train" 2>/dev/null
echo "sweep: $(( $(date +%s) - start )) s"
# what eval.keep reads back: each finished run's metrics, resolved config and manifest
find outputs \( -path "*/train/*" -o -path "*/synthesis/*" \) -not -path "*/.*" -name manifest.json -newer "$OUT/.sweep-start" \
  | xargs -r -n1 dirname | while read -r d; do
    for f in metrics.json config.yaml manifest.json; do [ -f "$d/$f" ] && echo "$d/$f"; done
  done > "$OUT/files.txt"
tar czf "$OUT/nof-sweep.tgz" -T "$OUT/files.txt"
