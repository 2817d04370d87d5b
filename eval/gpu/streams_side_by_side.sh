#!/usr/bin/env bash
# The MCL step with the top-share estimate on one stream (FORK=0) and on two (FORK=1, the default) on this tree, on the lent
# GPU after the packages are unpacked (../shared/tools/gpu/README.md) and with IRMCL_DATA set: three fr079 100k global
# runs hashed (two streams, one, two: the same files?), then the step benchmark alternately, two rounds. Everything
# lands in $OUT/step.tgz (docs/benchmarks.md, twenty-second session).
set -uo pipefail
export TQDM_DISABLE=1; ROOT=$PWD; W=$(mktemp -d)
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$W/device.txt"
for run in 1:1 0:1 1:2; do
  f=${run%%:*}; k=${run##*:}; d=$W/f-$f-$k; mkdir -p $d
  (cd $d && FORK=$f timeout 100 python $ROOT/eval/gpu/second_stream.py localize \
    +exp=fr079 mcl.weighting=likelihood_field localize.mode=global localize.num_starts=2 localize.run_s=8 \
    mcl.num_particles=100000 device=cuda:0 > $d.log 2>&1 || tail -3 $d.log)
  (cd $d && find . -name "start*.tum" | sort | xargs sha256sum | cut -c1-16 | tr '\n' ' ' | sed "s/^/fork $f run $k /"; echo) | tee -a $W/g100k.txt
done
rm -rf $W/f-*/
for round in 1 2; do
  for f in 0 1; do
    FORK=$f timeout 110 python eval/gpu/second_stream.py bench --device cuda:0 --particles 100000 1000000 --variants \
      warp+et+beam table likelihood_field --step-graph on --repeats 5 --torch-max 0 --out $W/bench-$f-$round > $W/bench-$f-$round.log 2>&1
    grep "graph |" $W/bench-$f-$round.log | sed "s/^/fork $f round $round /"
  done
done
tar czf "$OUT/step.tgz" -C "$W" .
