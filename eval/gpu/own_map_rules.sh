#!/usr/bin/env bash
# Issue 33 on the lent GPU: one real log localized in its own SLAM map under several lost-robot thresholds side by
# side (worlds.lost_agreement_below, and with "BxU" lost_agreement_updates U, which an own-map run reads from
# conf/exp/worlds.yaml), every run at once.
# Each threshold gets a copy of the tree whose conf/exp/worlds.yaml says it: a run's identity includes that file, so
# the runs of two thresholds never share a folder. Scored as eval/gpu/own_slam_map.sh scores (eval.analyses.own_slam_map).
# Usage (after the packages and the log are unpacked: ../shared/tools/gpu/README.md):
#   RULES="0.4 0.7" LOG=mit_killian SEEDS=0,1,2,3,4 N=20000 OUT=$PWD/gpu-out bash eval/gpu/own_map_rules.sh
# RUN_S: seconds of the log (default null: the whole log).
# CALIBRATION: a confidence calibration (eval.confidence fit) the copies judge with instead of the shipped one for N
# (irmcl_warp/mcl/calibration/likelihood_field.json at 20k): two calibrations side by side are two calls, each
# with its own OUT; the runs' identity includes the file, so they never share a folder.
# SLAM_ARGS as in eval/gpu/own_slam_map.sh (MIT Killian's converged map: seed 6, 60 particles, gmapping_code).
# Results: $OUT/own_slam_map-<log>-rule<v>.json and $OUT/own_map_rule<v>.tgz (the runs' trajectories, metrics,
# settings and spread.csv, the confidence per scan that eval.analyses.reference_fit scores) per threshold.
# OUT must be an absolute path (the runs start inside the copies).
set -uo pipefail
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
export PYTHONUNBUFFERED=1 TQDM_DISABLE=1
# one thread a run unless told otherwise: ten runs of 16 threads each swamped a 16-core host (load 78)
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} MKL_NUM_THREADS=${MKL_NUM_THREADS:-1} OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
LOG=${LOG:-mit_killian}; N=${N:-20000}; SEEDS=${SEEDS:-0,1,2,3,4}; RULES=${RULES:-0.4 0.7}; RUN_S=${RUN_S:-null}
SLAM_ARGS=${SLAM_ARGS:-slam.num_particles=60 slam.proposal=gmapping_code slam.seed=6}
ROOT=$PWD
# shellcheck disable=SC2086
python -m irmcl_warp.slam +exp="gmapping_$LOG" $SLAM_ARGS 2>&1 | grep -E "ATE|relations|Error" | tail -3
slam=$(dirname "$(ls -td outputs/gmapping_"$LOG"/slam/*/map.yaml | head -1)")
echo "=== $LOG in $slam/map.yaml: $N particles, seeds $SEEDS, lost below $RULES"
trees=()
for v in $RULES; do
  tree=$(mktemp -d); trees+=("$tree")
  cp -a irmcl_warp conf eval kernels hydra_plugins pyproject.toml "$tree"/
  below=${v%x*}; updates=${v#*x}  # "0.4" or "0.4x3" (below 0.4 for 3 updates in a row)
  sed -i "s/^  lost_agreement_below: .*/  lost_agreement_below: $below/" "$tree/conf/exp/worlds.yaml"
  [ "$updates" = "$v" ] || sed -i "s/^  lost_agreement_updates: .*/  lost_agreement_updates: $updates/" "$tree/conf/exp/worlds.yaml"
  grep -q "^  lost_agreement_below: $below$" "$tree/conf/exp/worlds.yaml" || { echo "could not set the rule $v"; exit 1; }
  if [ -n "${CALIBRATION:-}" ]; then
    cal="$tree/irmcl_warp/mcl/calibration/likelihood_field$([ "$N" = 20000 ] || echo "-$((N / 1000))k").json"
    cp "$CALIBRATION" "$cal" && echo "rule $v judged by $CALIBRATION ($cal)"
  fi
  for s in ${SEEDS//,/ }; do  # run inside the copy: python -m imports the package from the working directory
    # shellcheck disable=SC2086
    (cd "$tree" && python -m irmcl_warp.localize +exp="$LOG" mcl=amcl mcl.num_particles="$N" \
      localize.map_path="$ROOT/$slam/map.yaml" localize.run_s="$RUN_S" mcl.seed="$s" ${LOCALIZE_ARGS:-} \
      > "$OUT/localize-rule$v-seed$s.log" 2>&1) &
  done
done
wait
i=0
for v in $RULES; do
  tree=${trees[$i]}; i=$((i + 1))
  grep -hE "localized|Error" "$OUT"/localize-rule"$v"-seed*.log | sed "s/ -> .*//; s/^/rule $v: /" | tail -6
  runs=$(grep -hoE "( -> |^)outputs/$LOG/localize/[^ :]*" "$OUT"/localize-rule"$v"-seed*.log | sed 's/^ -> //' | sort -u)
  # shellcheck disable=SC2086
  (cd "$tree" && python -m eval.analyses.own_slam_map --slam "$ROOT/$slam" --runs $runs \
    --out "$OUT/own_slam_map-$LOG-rule$v.json" | tail -4)
  (cd "$tree" && find outputs -path "*/localize/*-in-map-*" \( -name trajectory.tum -o -name metrics.json \
    -o -name config.yaml -o -name manifest.json -o -name spread.csv \) | tar czf "$OUT/own_map_rule$v.tgz" -T -)
done
