#!/usr/bin/env bash
# Run the authors' IR-MCL main.py on every start a prepared folder holds (python -m eval.reference.irmcl
# --stage prepare writes them), here or on a GPU machine: it needs only their tree (bash
# eval/reference/build_irmcl.sh) and a Python with torch and what their script imports, no part of ours.
#
#   bash eval/reference/run_irmcl.sh OUTDIR [PYTHON]
#
# Per start: OUTDIR/start<k>.log (what main.py prints) and OUTDIR/start<k>.wall (its wall time, s); their
# estimate lands in OUTDIR/start<k>/IRMCL.txt. The configuration's paths are relative to their tree.
set -uo pipefail
OUT=$(cd "${1:?give the prepared folder}" && pwd)
PY=${2:-$(cd "$(dirname "$0")/../.." && pwd)/outputs/reference/irmcl/venv/bin/python}
SRC=$(cd "$(dirname "$0")/../.." && pwd)/outputs/reference/irmcl/src
test -f "$SRC/main.py" || { echo "$SRC: their code is not set up (bash eval/reference/build_irmcl.sh <clone>)" >&2; exit 1; }
for conf in "$OUT"/start*/loc.yml; do
  k=$(basename "$(dirname "$conf")")
  t0=$(date +%s%N)
  (cd "$SRC" && PYTHONPATH="$SRC/mcl/srrg_utils${PYTHONPATH:+:$PYTHONPATH}" "$PY" main.py --config_file "$conf") > "$OUT/$k.log" 2>&1
  code=$?
  ms=$(( ($(date +%s%N) - t0) / 1000000 ))
  printf '%d.%03d %d\n' $((ms / 1000)) $((ms % 1000)) "$code" > "$OUT/$k.wall"
  echo "$k: exit $code, $(cut -d' ' -f1 "$OUT/$k.wall") s"
done
