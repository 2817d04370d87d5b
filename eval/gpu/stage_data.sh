#!/usr/bin/env bash
# Pack what the MCL runs need without the raw logs into .gpu/c/data.tgz: per experiment the stream
# caches, the NOF checkpoints and the baked NOGs (run the localize stage once here first to make them).
set -euo pipefail
mkdir -p .gpu/c
tar czf .gpu/c/data.tgz outputs/{sim_office,fr079,intel,mit_csail}/stream outputs/fr079/nog \
  outputs/sim_office/train-quick/nof.pt outputs/fr079/train-paper/nof.pt outputs/intel/train-paper/nof.pt \
  outputs/mit_csail/train-fast/nof.pt
ls -la .gpu/c
