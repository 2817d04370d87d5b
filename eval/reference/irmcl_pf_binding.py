"""The module the authors' pf_utils.py imports (``pf_library.pybind.pf_library_pybind``), served through ctypes
from their C++ library (eval/reference/irmcl_pf_shim.cpp) instead of their pybind11 build. build_irmcl.sh copies
this file into their tree as pf_library/pybind/pf_library_pybind.py; it is the only Python of ours there."""

import ctypes
from pathlib import Path

import numpy as np

_lib = ctypes.CDLL(str(Path(__file__).with_name("libpf_library.so")))
_lib.pf_new.restype = ctypes.c_void_p
_lib.pf_free.argtypes = [ctypes.c_void_p]
_f64, _i32 = np.ctypeslib.ndpointer(np.float64, flags="C"), np.ctypeslib.ndpointer(np.int32, flags="C")
_lib.pf_predict.argtypes = [ctypes.c_void_p, _f64, ctypes.c_int, _f64, _f64]
_lib.pf_resample.argtypes = [ctypes.c_void_p, _f64, ctypes.c_int, _i32]


class _Vector4dVector:
    """Their std::vector<Eigen::Vector4d>: here the particles as an [n, 4] float64 array."""

    def __init__(self, particles):
        self.array = np.ascontiguousarray(particles, dtype=np.float64).reshape(-1, 4)

    def __array__(self, dtype=None, copy=None):
        return self.array if dtype is None else self.array.astype(dtype)


class _MotionModelAndResampling:
    def __init__(self):
        self._pf = _lib.pf_new()

    def __del__(self):
        if getattr(self, "_pf", None):
            _lib.pf_free(self._pf)

    def _predict(self, positions, control):
        src = positions.array if isinstance(positions, _Vector4dVector) else _Vector4dVector(positions).array
        out = np.empty_like(src)
        _lib.pf_predict(self._pf, src, len(src), np.ascontiguousarray(control, dtype=np.float64), out)
        return _Vector4dVector(out)

    def _resample_uniform(self, weights):
        w = np.ascontiguousarray(weights, dtype=np.float64)
        out = np.empty(len(w), np.int32)
        _lib.pf_resample(self._pf, w, len(w), out)
        return out
