#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# GMapping runs on one GPU box, several processes at a time (each run is bound by Python launch overhead,
# not by the GPU): one line of overrides per run, from the job lists below, through xargs -P.
#   bash eval/gpu/slam_sweep.sh main      # intel, fr079, mit_csail x paper, gmapping_code x 10 seeds, 30 particles
#   bash eval/gpu/slam_sweep.sh particles # intel: particles 5..60 x (paper+selective, paper+always, odometry+selective)
#   bash eval/gpu/slam_sweep.sh killian   # mit_killian (10 cm grid): paper+selective, 30 and 60 particles
#   bash eval/gpu/slam_sweep.sh replay    # intel and fr079 seed 0, each run twice: are the trajectories identical?
#   LIST=jobs.txt bash eval/gpu/slam_sweep.sh list  # one line of overrides per run from a file: e.g. every kept
#                                         # run again after the code changed (python -m eval.analyses.rerun > jobs.txt)
# Env: JOBS (parallel processes, default 8; killian 2; list 12), SWEEP_TIMEOUT (s: stop starting runs then and
# pack the finished ones; a later call with the same list runs only what is not finished), SEEDS (default 0..9), EXTRA (more overrides for every
# run of the sweep, e.g. "slam.free_check=false"; each is a run of its own), main only: LOGS, PROPOSALS; TAG
# (appended to the archive's name). Data: the logs staged beside the code (eval/gpu/stage_data.sh), IRMCL_DATA
# pointing at them. Results: $OUT/slam-<what>.tgz.
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
what=${1:?main, particles or killian}
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
SEEDS=${SEEDS:-"0 1 2 3 4 5 6 7 8 9"}
jobs=$(mktemp)
case "$what" in
  main)
    for exp in ${LOGS:-gmapping_intel gmapping_fr079 gmapping_mit_csail}; do for p in ${PROPOSALS:-paper gmapping_code}; do for s in $SEEDS; do
      echo "+exp=$exp slam.proposal=$p slam.seed=$s ${EXTRA:-}"; done; done; done > "$jobs"; P=${JOBS:-8} ;;
  replay)
    for exp in gmapping_intel gmapping_fr079; do
      for k in 1 2; do
        python -m irmcl_warp.slam device=cuda:0 +exp=$exp slam.seed=0 ${EXTRA:-} 2>&1 | grep -E "scans processed|Error" | tail -1
        run=$(ls -d outputs/$exp/slam/paper-selective-30p-seed0-* | head -1)
        md5sum "$run/trajectory.tum" | sed "s|^|$exp run $k: |"; rm -rf "$run"
      done
    done
    exit 0 ;;
  particles)
    for s in $SEEDS; do
      for n in 5 10 15 60; do echo "+exp=gmapping_intel slam.num_particles=$n slam.seed=$s ${EXTRA:-}"; done
      for n in 5 10 15 30 60; do echo "+exp=gmapping_intel slam.num_particles=$n slam.resample=always slam.seed=$s ${EXTRA:-}"; done
      for n in 5 10 15 30 60; do echo "+exp=gmapping_intel slam.num_particles=$n slam.proposal=odometry slam.seed=$s ${EXTRA:-}"; done
    done > "$jobs"; P=${JOBS:-8} ;;
  killian)
    for s in $SEEDS; do for n in ${PARTICLES:-30 60}; do echo "+exp=gmapping_mit_killian slam.num_particles=$n slam.seed=$s ${EXTRA:-}"; done; done \
      > "$jobs"; P=${JOBS:-2} ;;
  list)
    cp "${LIST:?LIST: a file with one line of overrides per run}" "$jobs"; P=${JOBS:-12} ;;
  *) echo "unknown sweep $what"; exit 2 ;;
esac
echo "$(wc -l < "$jobs") runs, $P at a time"
touch "$OUT/.sweep-start"
# one run first: Warp compiles the kernels into its cache once, not in every process at the same time
head -1 "$jobs" | xargs python -m irmcl_warp.slam device=cuda:0 2>&1 | grep -E "scans processed|Error" | tail -2
start=$(date +%s)
# a run already finished here (same settings) returns at once: the slam stage skips up-to-date folders
tail -n +2 "$jobs" | timeout "${SWEEP_TIMEOUT:-0}" xargs -P "$P" -I{} sh -c \
  'python -m irmcl_warp.slam device=cuda:0 {} 2>&1 | grep -E "scans processed|Error" | tail -1'
pkill -f "python -m irmcl_warp.slam" 2>/dev/null  # runs the timeout stopped: unfinished, not packed
echo "sweep $what: $(( $(date +%s) - start )) s for $(( $(wc -l < "$jobs") - 1 )) runs with $P processes"
# the runs finished by this call (a stopped run leaves no metrics.json, and its folder is not packed)
find outputs -path "*/slam/*" -not -path "*/.*" -name manifest.json -newer "$OUT/.sweep-start" | xargs -r -n1 dirname | while read -r d; do
  for f in metrics.json config.yaml manifest.json neff.csv map.png; do [ -f "$d/$f" ] && echo "$d/$f"; done
done > "$OUT/files-$what.txt"
[ -n "${TRAJECTORIES:-}" ] && find outputs -path "*/slam/*" -not -path "*/.*" -name trajectory.tum >> "$OUT/files-$what.txt"  # large: only when asked
tar czf "$OUT/slam-$what${TAG:-}.tgz" -T "$OUT/files-$what.txt"
ls -la "$OUT"
