// Samples of the released GMapping's motion model (MotionModel::drawFromMotion(p, pnew, pold)), for the
// differential check in eval/reference/gmapping.py (--motion). Written for irmcl-warp; links the released code.
//
// usage: gmapping_motion srr srt str stt px py pth newx newy newth oldx oldy oldth N seed
//   prints N lines "x y theta": the pose p moved by the odometry step from old to new, with noise
#include <cstdlib>
#include <iomanip>
#include <iostream>

#include "gmapping/gridfastslam/motionmodel.h"
#include "gmapping/utils/stat.h"

int main(int argc, char** argv) {
  if (argc != 16) {
    std::cerr << "usage: gmapping_motion srr srt str stt px py pth newx newy newth oldx oldy oldth N seed\n";
    return 2;
  }
  double v[13];
  for (int i = 0; i < 13; ++i) v[i] = std::atof(argv[i + 1]);
  long n = std::atol(argv[14]);
  GMapping::MotionModel m;
  m.srr = v[0];
  m.srt = v[1];
  m.str = v[2];
  m.stt = v[3];
  GMapping::sampleGaussian(1, std::strtoul(argv[15], nullptr, 10));
  GMapping::OrientedPoint p(v[4], v[5], v[6]), pnew(v[7], v[8], v[9]), pold(v[10], v[11], v[12]);
  std::cout << std::setprecision(12);
  for (long i = 0; i < n; ++i) {
    GMapping::OrientedPoint q = m.drawFromMotion(p, pnew, pold);
    std::cout << q.x << " " << q.y << " " << q.theta << "\n";
  }
  return 0;
}
