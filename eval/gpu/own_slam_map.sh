#!/usr/bin/env bash
# Issue 33 on the lent GPU: every real log localized globally from its first scan, over the whole log, in its own
# SLAM map (GMapping with the experiment's settings), mcl=amcl with N particles (default 100k), one run per seed;
# each run scored against the SLAM run's poses of the same scans (python -m eval.analyses.own_slam_map).
# Usage (after the packages and the logs are unpacked: ../shared/tools/gpu/README.md, eval/gpu/stage_data.sh):
#   LOGS="fr079 intel" SEEDS=0,1,2,3,4 bash eval/gpu/own_slam_map.sh
# SLAM_ARGS: overrides of the SLAM run (MIT Killian: "slam.num_particles=60 slam.proposal=gmapping_code slam.seed=6",
# a seed whose map converged, 0.045 m on the relations: the experiment's 30-particle map did not, 0.19 m);
# JOBS: localization runs at once (separate processes sharing the GPU; each run is host-bound), default 1.
# LOCALIZE_ARGS: more overrides of the localization runs (e.g. "mcl.global_candidates=10").
# Results: $OUT/own_slam_map-<log>.json (the scores) and $OUT/own_slam_map.tgz (the runs' trajectories, metrics and
# settings, the SLAM runs' maps and poses; not the MCAP replays or animations). Unpack into the repository root.
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
export PYTHONUNBUFFERED=1 TQDM_DISABLE=1
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
N=${N:-100000}
SEEDS=${SEEDS:-0,1,2,3,4,5,6,7,8,9}
JOBS=${JOBS:-1}
for log in ${LOGS:-fr079 intel mit_csail}; do
  echo "=== $log: SLAM"
  # shellcheck disable=SC2086
  python -m irmcl_warp.slam +exp="gmapping_$log" ${SLAM_ARGS:-} 2>&1 | grep -E "ATE|relations|scans processed|Error" | tail -3
  slam=$(dirname "$(ls -td outputs/gmapping_"$log"/slam/*/map.yaml | head -1)")
  echo "=== $log: localized in $slam/map.yaml, $N particles, seeds $SEEDS, $JOBS at once"
  localize=(+exp="$log" mcl=amcl mcl.num_particles="$N" localize.map_path="$slam/map.yaml" localize.run_s=null)
  # shellcheck disable=SC2206
  localize+=(${LOCALIZE_ARGS:-})
  if [ "$JOBS" -gt 1 ]; then
    for s in ${SEEDS//,/ }; do
      python -m irmcl_warp.localize "${localize[@]}" mcl.seed="$s" > "$OUT/localize-$log-seed$s.log" 2>&1 &
      while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do sleep 1; done
    done
    wait
  else
    python -m irmcl_warp.localize -m "${localize[@]}" mcl.seed="$SEEDS" > "$OUT/localize-$log-seeds.log" 2>&1
  fi
  grep -hE "localized|Error" "$OUT"/localize-"$log"-seed*.log | sed 's/ -> .*//' | tail -12
  # the runs these seeds made or reused (each names its folder last), not every run ever made in this map: a run
  # judged by another calibration or with other settings is another run in the same map
  runs=$(grep -hoE "( -> |^)outputs/$log/localize/[^ :]*" "$OUT"/localize-"$log"-seed*.log | sed 's/^ -> //' | sort -u)
  python -m eval.analyses.own_slam_map --slam "$slam" --runs $runs --out "$OUT/own_slam_map-$log.json" | tail -14
done
find outputs -path "*/localize/*-in-map-*" \( -name trajectory.tum -o -name metrics.json -o -name config.yaml \
  -o -name manifest.json -o -name spread.csv -o -name run.png \) > "$OUT/own-files.txt"
find outputs -path "*/slam/*" \( -name trajectory.tum -o -name "map.*" -o -name metrics.json -o -name config.yaml \
  -o -name manifest.json \) >> "$OUT/own-files.txt"
tar czf "$OUT/own_slam_map.tgz" -T "$OUT/own-files.txt"
