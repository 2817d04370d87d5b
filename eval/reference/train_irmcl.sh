#!/usr/bin/env bash
# Train a NOF with the authors' recipe and script (their train.py, shells/pretraining/fr079.sh's settings) on
# a folder that python -m eval.reference.irmcl --stage nof-data prepared (our split as their train/val/test.json).
# It runs here or on a GPU machine (their Trainer asks for a GPU): it needs their tree (build_irmcl.sh), a
# Python with torch, pytorch-lightning 1.9 and what their code imports; where open3d is missing,
# eval/reference/irmcl_open3d_stub stands in for the three calls they make to it.
#
#   bash eval/reference/train_irmcl.sh DATA_DIR EPOCHS [PYTHON]
#
# Their logs and checkpoints land in DATA_DIR/../logs/nof/version_0/ (best.ckpt by validation error, last.ckpt).
set -euo pipefail
DATA=$(cd "${1:?give the prepared data folder}" && pwd)
EPOCHS=${2:?give the number of epochs (theirs: 32)}
HERE=$(cd "$(dirname "$0")" && pwd)
PY=${3:-$HERE/../../outputs/reference/irmcl/venv/bin/python}
SRC=$HERE/../../outputs/reference/irmcl/src
RUN=$(dirname "$DATA")
if ! "$PY" -c "import open3d" 2>/dev/null; then export PYTHONPATH="$HERE/irmcl_open3d_stub${PYTHONPATH:+:$PYTHONPATH}"; fi
cd "$SRC"
rm -rf logs/nof
# their fr079.sh, the epochs given
"$PY" -W ignore train.py --root_dir "$DATA" --N_samples 256 --perturb 1 --noise_std 0 --L_pos 10 \
  --feature_size 256 --use_skip --seed 42 --batch_size 1024 --chunk 262144 \
  --num_epochs "$EPOCHS" --loss_type smoothl1 --optimizer adam --weight_decay 1e-3 \
  --lr 1e-4 --decay_step 4 8 --decay_gamma 0.5 --lambda_opacity 1e-5 \
  --exp_name nof
rm -rf "$RUN/logs" && mkdir -p "$RUN/logs" && cp -r logs/nof "$RUN/logs/"
