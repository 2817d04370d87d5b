#!/usr/bin/env bash
# Pack what the authors' IR-MCL scripts need on an offline GPU machine (Python 3.12 with torch, numpy and
# matplotlib, nothing else; one transfer carries at most 64 MiB): the wheels their code imports and a tar of
# their tree with the prepared inputs. Run after build_irmcl.sh and the prepare / nof-data stages.
#
#   bash eval/reference/gpu_irmcl_bundle.sh OUTDIR...       -> .gpu/irmcl/{wheels/,inputs.tar.xz}
#
# OUTDIR: prepared folders (outputs/<exp>/reference-irmcl-tracking-10k, outputs/<exp>/reference-irmcl-nof, ...).
# On the GPU machine (carry .gpu/irmcl), from the project root:
#   tar xJf .gpu/irmcl/inputs.tar.xz && mkdir -p /root/s && python3 -c "import zipfile, glob;
#     [zipfile.ZipFile(w).extractall('/root/s') for w in glob.glob('.gpu/irmcl/wheels/*.whl')]"
#   export PYTHONPATH=/root/s
#   bash eval/reference/run_irmcl.sh outputs/<exp>/reference-irmcl-tracking-10k python3      (their MCL)
#   bash eval/reference/train_irmcl.sh outputs/<exp>/reference-irmcl-nof/data 10 python3      (their training)
# then bring back start*.log, start*.wall, start*/IRMCL.txt or the logs/ folder (tar them into $OUT).
# Run their scripts from their tree or the project root, not from elsewhere with the project on the path: the
# GPU image's transformers imports any package named "kernels".
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
BUNDLE=$ROOT/.gpu/irmcl
rm -rf "$BUNDLE" && mkdir -p "$BUNDLE/wheels"
# what their main.py, eval and train.py import beyond torch / numpy / matplotlib, for CPython 3.12 on x86-64;
# evo 1.30 (1.38 refuses their positional max_diff), pytorch-lightning 2.5 (1.9 fails under NumPy 2)
pip download -q --no-deps --python-version 3.12 --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux_2_27_x86_64 --platform manylinux_2_28_x86_64 --only-binary=:all: -d "$BUNDLE/wheels" \
  evo==1.30.6 rosbags lz4 ruamel.yaml zstandard backports.zstd apsw natsort colorama argcomplete pygments \
  typing_extensions packaging scipy pyyaml pytorch-lightning==2.5.5 torchmetrics==1.8.2 lightning-utilities==0.15.2 \
  tensorboardX protobuf fsspec tqdm setuptools==69.5.1
rel=()
for d in "$@"; do rel+=("$(realpath --relative-to="$ROOT" "$d")"); done
(cd "$ROOT" && tar cJf "$BUNDLE/inputs.tar.xz" outputs/reference/irmcl/src "${rel[@]}")
du -sh "$BUNDLE"
