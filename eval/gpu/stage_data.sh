#!/usr/bin/env bash
# Pack the real logs the GPU runs read into .gpu/c/data.tgz (the GPU machine cannot see ../shared): a run's
# identity is the content of its input files (irmcl_warp/runs.py), so the logs go along, not caches made here.
# On the GPU machine: tar xzf .gpu/c/data.tgz -C /tmp && export IRMCL_DATA=/tmp/data. Add finished training runs
# the MCL runs consume with EXTRA="outputs/fr079/train outputs/intel/train ...".
set -euo pipefail
mkdir -p .gpu/c
DATA=${IRMCL_DATA:-../shared/data}
tar czf .gpu/c/data.tgz -C "$(dirname "$DATA")" \
  "$(basename "$DATA")"/kuemmerle2009/derived "$(basename "$DATA")"/kuemmerle2009/relations \
  "$(basename "$DATA")"/kuemmerle2009/bags/fr079.bag "$(basename "$DATA")"/kuemmerle2009/bags/intel.bag \
  "$(basename "$DATA")"/kuemmerle2009/bags/mit-csail.bag "$(basename "$DATA")"/kuemmerle2009/bags/mit-killian.bag \
  "$(basename "$DATA")"/kuemmerle2009/killian.g2o.zip \
  "$(basename "$DATA")"/corrected/matched "$(basename "$DATA")"/splits ${EXTRA:-}
ls -la .gpu/c
