#!/usr/bin/env bash
# Back on this machine: extract the returned archive (e.g. into /tmp/gpu) and keep its run folders in the
# repository with python -m eval.keep /tmp/gpu/outputs/<exp>/<run>... (results/<group>/<exp>.json).
# One GPU session of MCL measurements (docs/benchmarks.md). Usage: bash eval/gpu/mcl.sh <part>...
#   bench    python -m eval.bench mcl on the fr079 NOG (10k / 100k / 1M particles, the torch reference)
#   global   global localization, 100k particles: every dataset x {nog_raymarch, likelihood_field,
#            beam_model} x {5, 10 cm} (Hydra multirun)
#   tracking the same with 10k particles from a noisy initial pose
#   real     issue 18: a real fr079 global run (100k particles kept, train=fast) beside the micro-benchmark
#            on its own NOG, the same filter settings, the step as a graph
#   motion   issue 17: global localization, 100k particles, train=fast, NOG and likelihood field with Thrun's and
#            the authors' motion model (mcl.motion=odometry,irmcl), fr079 and intel
#   width    issue 17: the NOG with the authors' motion model and sigma 0.25 m (the likelihood field's heading width
#            per scan, docs/fidelity.md), global, 100k, train=fast, fr079 and intel
#   hw       issue 36: fr079's NOF (train=fast) and its NOG, then the step benchmark on that NOG: the march,
#            the table, and AMCL's grid models at 10k / 100k / 1M, 5 repeats, the torch reference up to 100k; the NOF
#            and NOG come back in $OUT/fr079-nof-nog.tgz for the CPU measurements (python -m eval.bench mcl --device cpu)
#   kidnap   tracking runs teleported 30 s in, recovery on, sim_office and fr079, nog_raymarch and likelihood_field
#   table    issue 18: mcl.weighting=nog_table beside nog_raymarch: the step benchmark on the fr079 NOG (10k / 100k /
#            1M, the torch reference) and global (100k) and tracking (10k) runs on fr079 and intel, train=fast
#            (their training runs and NOGs carried in outputs/<exp>/{train,nog})
# EXPS (default "sim_office fr079 intel mit_csail") and EXTRA (more overrides) narrow a run; results are
# packed into $OUT/mcl-results.tgz (the machine returns only a few files).
set -uo pipefail
# the commit this copy of the tree was made from, for the runs' manifests (written here by eval/gpu/stamp_source.sh)
[ -f .gpu/b/source_env.sh ] && source .gpu/b/source_env.sh
OUT=${OUT:-gpu-out}; mkdir -p "$OUT"
EXPS=${EXPS:-"sim_office fr079 intel mit_csail"}
preset() { case "$1" in fr079|intel) echo paper;; mit_csail) echo fast;; *) echo quick;; esac; }
sweep() {  # mode particles extra...
  local mode=$1 n=$2; shift 2
  for exp in $EXPS; do
    echo "=== $exp $mode $n"
    python -m irmcl_warp.localize -m +exp="$exp" train="$(preset "$exp")" localize.mode="$mode" mcl.num_particles="$n" \
      "$@" ${EXTRA:-} 2>&1 | grep -E "^start|success|Error|error" | grep -v "^\[" | tail -40
  done
}
for part in "$@"; do
  case "$part" in
    bench) python -m eval.bench mcl --device cuda:0 --nog "$(ls outputs/fr079/nog/nog-*.npz | head -1)" \
             --out "$OUT/bench" 2>&1 | tail -16 ;;
    global) sweep global "${N_GLOBAL:-100000}" mcl.weighting=nog_raymarch,likelihood_field,beam_model mcl.map_resolution_m=0.05,0.1 ;;
    tracking) sweep tracking "${N_TRACK:-10000}" mcl.weighting=nog_raymarch,likelihood_field,beam_model mcl.map_resolution_m=0.05,0.1 ;;
    real) python -m irmcl_warp.train +exp=fr079 train=fast 2>&1 | grep -v "^\[" | tail -3
          python -m irmcl_warp.localize +exp=fr079 train=fast localize.mode=global mcl.num_particles=100000 \
            mcl.weighting=nog_raymarch mcl.reduce_to=0 localize.num_starts=${STARTS:-3} 2>&1 | grep -E "start|ms|Error" | tail -8
          python -m eval.bench mcl --device cuda:0 --nog "$(ls outputs/fr079/nog/nog-*.npz | head -1)" --particles 100000 \
            --variants warp+et warp+et+beam warp+et+skip+beam --step-graph both --torch-max 0 --out "$OUT/bench-fr079" \
            2>&1 | tail -10
          tar czf "$OUT/fr079-nof-nog.tgz" outputs/fr079/train/fast-* outputs/fr079/nog ;;
    motion) for exp in fr079 intel; do
              python -m irmcl_warp.train +exp="$exp" train=fast 2>&1 | grep -E "best|up to date|Error"  # found when finished
              python -m irmcl_warp.localize -m +exp="$exp" train=fast localize.mode=global mcl.num_particles=100000 \
                mcl.weighting=nog_raymarch,likelihood_field mcl.motion=odometry,irmcl 2>&1 | grep -E "success|Error"
            done
            find outputs -path "*/localize/*-global-100k-*" \( -name metrics.json -o -name config.yaml -o -name manifest.json \
              -o -name "*.tum" \) \
              > "$OUT/motion-files.txt"
            tar czf "$OUT/motion-results.tgz" -T "$OUT/motion-files.txt" outputs/intel/train/fast-* ;;
    width) for exp in fr079 intel; do
             python -m irmcl_warp.localize +exp="$exp" train=fast localize.mode=global mcl.num_particles=100000 \
               mcl.weighting=nog_raymarch mcl.motion=irmcl mcl.sigma_m=0.25 2>&1 | grep -E "success|Error"
           done
           find outputs -path "*/localize/*-global-100k-*" -newer "$OUT" \( -name metrics.json -o -name config.yaml \
             -o -name manifest.json -o -name "*.tum" \) \
             > "$OUT/width-files.txt"
           tar czf "$OUT/width-results.tgz" -T "$OUT/width-files.txt" ;;
    table) python -m eval.bench mcl --device cuda:0 --nog "$(ls outputs/fr079/nog/nog-*.npz | head -1)" \
             --variants warp+et+beam warp+et+skip+beam table table360 --step-graph on --out "$OUT/bench-table" 2>&1 \
             | grep -v "^{" | tail -22
           for exp in ${TABLE_EXPS:-fr079 intel}; do
             python -m irmcl_warp.localize -m +exp="$exp" train=fast localize.mode=global mcl.num_particles=100000 \
               mcl.weighting=nog_raymarch,nog_table 2>&1 | grep -E "success|Error|ms"
             python -m irmcl_warp.localize -m +exp="$exp" train=fast localize.mode=tracking mcl.num_particles=10000 \
               mcl.weighting=nog_raymarch,nog_table 2>&1 | grep -E "success|Error|ms"
           done ;;
    hw) python -m irmcl_warp.train +exp=fr079 train=fast 2>&1 | grep -v "^\[" | tail -3
        python -m irmcl_warp.localize +exp=fr079 train=fast localize.mode=tracking localize.num_starts=1 localize.run_s=5 \
          mcl.num_particles=1000 mcl.weighting=nog_raymarch 2>&1 | grep -E "success|Error" | tail -3  # bakes the NOG
        python -m eval.bench mcl --device cuda:0 --nog "$(ls outputs/fr079/nog/nog-*.npz | head -1)" --step-graph on \
          --variants warp+et+beam table likelihood_field beam_model --repeats 5 --torch-max 100000 --out "$OUT/bench-hw" \
          2>&1 | grep -v "^{" | tail -24
        tar czf "$OUT/fr079-nof-nog.tgz" outputs/fr079/train/fast-* outputs/fr079/nog ;;
    kidnap) EXPS="sim_office fr079" sweep tracking "${N_TRACK:-10000}" mcl.weighting=nog_raymarch,likelihood_field \
              localize.kidnap_at_s=30 mcl.recovery_alpha_slow=0.01 mcl.recovery_alpha_fast=0.2 ;;
    *) echo "unknown part $part" >&2 ;;
  esac
done
# keep what the tables need: metrics, settings, the first start's plot and the trajectories
find outputs -path "*/localize/*" -not -path "*/.*" \( -name metrics.json -o -name config.yaml -o -name manifest.json -o -name start0.png \
  -o -name "*.tum" \) > "$OUT/files.txt"
tar czf "$OUT/mcl-results.tgz" -T "$OUT/files.txt" 2>/dev/null
ls -la "$OUT"
