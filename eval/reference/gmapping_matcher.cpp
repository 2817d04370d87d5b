// The released GMapping's scan matcher (ScanMatcher on a ScanMatcherMap) on given scans, for a differential test
// of ours (eval/reference/gmapping.py --matcher). Written for irmcl-warp; it links the released code, built outside
// the project by build_gmapping.sh.
//
// stdin, one command per line:
//   MAP xmin ymin xmax ymax delta            the map, as GridSlamProcessor makes it; prints
//                                            "MAP center_x center_y delta size_x2 size_y2"
//   LASER n lx ly ltheta a_1 ... a_n         beam angles and the laser's pose on the robot
//   PARAMS urange range sigma kernel lstep astep iterations lsigma lskip
//   R x y theta r_1 ... r_n                  register a scan at a pose (as processScan does for a particle)
//   S x y theta r_1 ... r_n                  prints "S score log_likelihood" (score(), likelihoodAndScore())
//   O x y theta r_1 ... r_n                  prints "O x y theta score": optimize() from the pose
//   C ix iy                                  prints "C hits visits mean_x mean_y" of a cell (map indices)
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "gmapping/scanmatcher/scanmatcher.h"

int main() {
  std::unique_ptr<GMapping::ScanMatcherMap> map;
  GMapping::ScanMatcher matcher;
  // its constructor leaves generateMap unset (the line that sets it sits inside a comment): the wrapper sets it
  // false (slam_gmapping.cpp), end points only, and so do we
  matcher.setgenerateMap(false);
  std::vector<double> angles;
  std::string line;
  std::cout << std::setprecision(17);
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string cmd;
    in >> cmd;
    if (cmd == "MAP") {
      double xmin, ymin, xmax, ymax, delta;
      in >> xmin >> ymin >> xmax >> ymax >> delta;
      map.reset(new GMapping::ScanMatcherMap(GMapping::Point(xmin + xmax, ymin + ymax) * .5, xmax - xmin, ymax - ymin,
                                             delta));
      GMapping::IntPoint origin = map->world2map(GMapping::Point(0, 0));
      GMapping::Point center = map->map2world(GMapping::IntPoint(map->getMapSizeX() / 2, map->getMapSizeY() / 2));
      std::cout << "MAP " << center.x << " " << center.y << " " << delta << " " << map->getMapSizeX() / 2 << " "
                << map->getMapSizeY() / 2 << " " << origin.x << " " << origin.y << "\n";
    } else if (cmd == "LASER") {
      unsigned n;
      double lx, ly, lt;
      in >> n >> lx >> ly >> lt;
      angles.resize(n);
      for (double& a : angles) in >> a;
      matcher.setLaserParameters(n, angles.data(), GMapping::OrientedPoint(lx, ly, lt));
    } else if (cmd == "PARAMS") {
      double urange, range, sigma, lstep, astep, lsigma;
      int kernel, iterations;
      unsigned lskip;
      in >> urange >> range >> sigma >> kernel >> lstep >> astep >> iterations >> lsigma >> lskip;
      matcher.setMatchingParameters(urange, range, sigma, kernel, lstep, astep, iterations, lsigma, lskip);
    } else if (cmd == "C" && map) {
      int ix, iy;
      in >> ix >> iy;
      const GMapping::PointAccumulator& c = map->cell(GMapping::IntPoint(ix, iy));
      std::cout << "C " << c.n << " " << c.visits << " " << (c.n ? c.mean().x : 0.0) << " " << (c.n ? c.mean().y : 0.0)
                << "\n";
    } else if (cmd == "R" || cmd == "S" || cmd == "O") {
      if (!map || angles.empty()) {
        std::cerr << "MAP and LASER come first\n";
        return 2;
      }
      GMapping::OrientedPoint pose;
      in >> pose.x >> pose.y >> pose.theta;
      std::vector<double> r(angles.size());
      for (double& v : r) in >> v;
      if (!in) {
        std::cerr << "line " << cmd << ": expected a pose and " << angles.size() << " ranges\n";
        return 2;
      }
      if (cmd == "R") {
        matcher.invalidateActiveArea();
        matcher.computeActiveArea(*map, pose, r.data());
        matcher.registerScan(*map, pose, r.data());
      } else if (cmd == "S") {
        double s = matcher.score(*map, pose, r.data()), s2, l;
        matcher.likelihoodAndScore(s2, l, *map, pose, r.data());
        std::cout << "S " << s << " " << l << "\n";
      } else {
        GMapping::OrientedPoint best;
        double s = matcher.optimize(best, *map, pose, r.data());
        std::cout << "O " << best.x << " " << best.y << " " << best.theta << " " << s << "\n";
      }
    } else if (!cmd.empty()) {
      std::cerr << "unknown command " << cmd << "\n";
      return 2;
    }
  }
  return 0;
}
