// A C interface to the authors' particle-filter library (their mcl/srrg_utils/pf_library/pybind/pf_library.cpp:
// the motion model and the low-variance resampler of IR-MCL's MCL), so that Python of any version reaches it
// through ctypes instead of their pybind11 module, which must be compiled for one Python. Their library is
// compiled unchanged beside this file by eval/reference/build_irmcl.sh; only this glue is ours.
#include "pf_library.h"

extern "C" {
void *pf_new() { return new pf_library::MotionModelAndResample(); }

void pf_free(void *pf) { delete static_cast<pf_library::MotionModelAndResample *>(pf); }

// particles: n rows of (x, y, yaw, weight); control: (dx, dy, dyaw) in the robot frame; out: n rows
void pf_predict(void *pf, const double *particles, int n, const double *control, double *out) {
  Vector4dVector in(n);
  for (int i = 0; i < n; ++i) in[i] = Eigen::Map<const Vector4d>(particles + 4 * i);
  Vector3d u(control[0], control[1], control[2]);
  Vector4dVector moved = static_cast<pf_library::MotionModelAndResample *>(pf)->predict(in, u);
  for (int i = 0; i < n; ++i) Eigen::Map<Vector4d>(out + 4 * i) = moved[i];
}

// weights: n; out: n indices of the particles drawn
void pf_resample(void *pf, const double *weights, int n, int *out) {
  std::vector<double> w(weights, weights + n);
  std::vector<int> idx = static_cast<pf_library::MotionModelAndResample *>(pf)->resample_uniform(w);
  for (int i = 0; i < n; ++i) out[i] = idx[i];
}
}
