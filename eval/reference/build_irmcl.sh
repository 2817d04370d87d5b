#!/usr/bin/env bash
# Set up the authors' IR-MCL code (github.com/PRBonn/ir-mcl) outside the project: its code never enters this
# repository. eval/reference/irmcl.py then runs their MCL on our logs.
#
#   bash eval/reference/build_irmcl.sh [SRC]
#
# SRC: a clone of https://github.com/PRBonn/ir-mcl (a work tree or a bare repository); default $IRMCL_SRC.
# The commit used for the figures is pinned below. Everything goes to outputs/reference/irmcl/ (git-ignored):
#   src/   their files at the pinned commit (the .ckpt weights are git-LFS-sized and may be absent: not needed)
#   venv/  Python with what their MCL imports (torch CPU, numpy, scipy, matplotlib, evo, pyyaml)
#   their particle-filter library (motion model and resampling, C++), built in src/mcl/ with a ctypes binding
#   of ours (irmcl_pf_shim.cpp, irmcl_pf_binding.py) in place of their pybind11 module
# Needs g++ and Eigen 3 (Debian: apt-get install libeigen3-dev). WITH_EVAL=1 also installs what their eval.py
# needs (open3d, about 400 MB) for python -m eval.reference.irmcl --stage synthesis; WITH_TRAIN=1 what their
# train.py needs (it asks for a GPU: see gpu_irmcl_bundle.sh for the offline GPU machine).
set -euo pipefail
PIN=aab8c91  # "Merge pull request #1 from PRBonn/dev", the newest commit of the repository
SRC=${1:-${IRMCL_SRC:?give the ir-mcl clone as an argument or in IRMCL_SRC}}
HERE=$(cd "$(dirname "$0")" && pwd)
OUT=${IRMCL_BUILD:-$HERE/../../outputs/reference/irmcl}
mkdir -p "$OUT"
rm -rf "$OUT/src" && mkdir -p "$OUT/src"
# every file but the weights, which a bare snapshot may lack (git archive still names them on stderr)
git -C "$SRC" ls-tree -r --name-only "$PIN" | grep -v '\.ckpt$' | xargs git -C "$SRC" archive "$PIN" -- 2>/dev/null | tar x -C "$OUT/src"
test -f "$OUT/src/main.py" || { echo "$SRC at $PIN: main.py missing, not their repository?" >&2; exit 1; }
echo "$PIN $(git -C "$SRC" rev-parse "$PIN")" > "$OUT/COMMIT"
EIGEN=${EIGEN_INCLUDE:-/usr/include/eigen3}
test -f "$EIGEN/Eigen/Core" || { echo "Eigen 3 headers not found in $EIGEN (apt-get install libeigen3-dev, or set EIGEN_INCLUDE)" >&2; exit 1; }
if [ ! -x "$OUT/venv/bin/python" ]; then
  python3 -m venv "$OUT/venv"
  "$OUT/venv/bin/pip" install -q torch==2.13.0  # the CPU build (a local file on the project's machines)
  "$OUT/venv/bin/pip" install -q numpy scipy matplotlib pyyaml evo==1.30.6  # their utils.py passes max_diff positionally, which evo 1.38 refuses
fi
if [ "${WITH_EVAL:-0}" = 1 ]; then  # their eval.py (Table I's metrics): open3d for the Chamfer distance, tqdm
  "$OUT/venv/bin/pip" install -q open3d tqdm  # (open3d also needs libusb-1.0-0 from Debian)
fi
if [ "${WITH_TRAIN:-0}" = 1 ]; then  # their train.py: pytorch-lightning 2.5 (1.9 fails under NumPy 2), its logger
  "$OUT/venv/bin/pip" install -q pytorch-lightning==2.5.5 torchmetrics==1.8.2 lightning-utilities==0.15.2 tensorboardX \
    "setuptools<70"
fi
PY="$OUT/venv/bin/python"
LIB="$OUT/src/mcl/srrg_utils/pf_library"
# their C++ library, unchanged, with a C interface of ours for ctypes instead of their pybind11 module (which
# would tie the build to one Python version: the GPU machines run another) (libstdc++ linked dynamically: a static one would need glibc 2.36)
g++ -O3 -DNDEBUG -std=c++17 -shared -fPIC -w -I"$EIGEN" -I"$LIB/pybind" \
  "$LIB/pybind/pf_library.cpp" "$HERE/irmcl_pf_shim.cpp" -o "$LIB/pybind/libpf_library.so"
cp "$HERE/irmcl_pf_binding.py" "$LIB/pybind/pf_library_pybind.py"
touch "$LIB/__init__.py" "$LIB/pybind/__init__.py"
(cd "$OUT/src/mcl/srrg_utils" && "$PY" -c "
import numpy as np
from pf_library.pf_utils import PfUtils
pf = PfUtils()
p = pf.motion_model(np.tile([0.0, 0.0, 0.0, 1.0], (1000, 1)), np.array([1.0, 0.0, 0.1]))
assert p.shape == (1000, 4) and abs(p[:, 0].mean() - 1.0) < 0.05 and p[:, 2].std() > 0, p[:3]
assert (pf.resample(np.column_stack([p[:, :3], np.r_[np.zeros(999), 1.0]]))[:, :3] == p[-1, :3]).all()")
echo "set up the authors' IR-MCL $(cat "$OUT/COMMIT") in $OUT"
