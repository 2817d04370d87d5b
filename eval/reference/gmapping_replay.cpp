// Replays a laser log through the released GMapping (GridSlamProcessor) the way its ROS wrapper
// (slam_gmapping) drives it, without ROS. Written for irmcl-warp; it links the released code, built outside the
// project by build_gmapping.sh.
//
// usage: gmapping_replay SCANS OUT_PATH OUT_NEFF [key=value ...]
//   SCANS:    one scan per line: "stamp x y theta n r_1 ... r_n", (x, y, theta) the laser's odometry pose
//   OUT_PATH: the best particle's path at the end, one processed scan per line: "stamp x y theta"
//   OUT_NEFF: one line per processed scan: "stamp neff"
//   keys: the wrapper's parameters (particles, sigma, kernelSize, lstep, astep, iterations, lsigma, ogain, lskip,
//         srr, srt, str, stt, linearUpdate, angularUpdate, temporalUpdate, resampleThreshold, delta, xmin, ymin,
//         xmax, ymax, llsamplerange, llsamplestep, lasamplerange, lasamplestep, minimumScore, maxRange, maxUrange,
//         angleIncrement, seed), with the wrapper's defaults; maxRange is required (the wrapper takes the scan's
//         range_max - 0.01), maxUrange defaults to it, angleIncrement to pi / (n - 1).
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "gmapping/gridfastslam/gridslamprocessor.h"
#include "gmapping/sensor/sensor_odometry/odometrysensor.h"
#include "gmapping/sensor/sensor_range/rangesensor.h"
#include "gmapping/utils/stat.h"

struct Scan {
  double stamp, x, y, theta;
  std::vector<double> ranges;
};

static std::vector<Scan> read_scans(const char* path) {
  std::ifstream in(path);
  if (!in) {
    std::cerr << path << ": cannot open\n";
    std::exit(2);
  }
  std::vector<Scan> scans;
  std::string line;
  size_t n_line = 0;
  while (std::getline(in, line)) {
    ++n_line;
    std::istringstream s(line);
    Scan scan;
    size_t n = 0;
    if (!(s >> scan.stamp >> scan.x >> scan.y >> scan.theta >> n)) {
      std::cerr << path << ", line " << n_line << ": expected 'stamp x y theta n ranges...'\n";
      std::exit(2);
    }
    scan.ranges.resize(n);
    for (size_t i = 0; i < n; ++i) {
      if (!(s >> scan.ranges[i])) {
        std::cerr << path << ", line " << n_line << ": expected " << n << " ranges\n";
        std::exit(2);
      }
    }
    scans.push_back(scan);
  }
  return scans;
}

int main(int argc, char** argv) {
  if (argc < 4) {
    std::cerr << "usage: gmapping_replay SCANS OUT_PATH OUT_NEFF [key=value ...]\n";
    return 2;
  }
  // the wrapper's defaults (slam_gmapping.cpp, SlamGMapping::init)
  std::map<std::string, double> p = {
      {"particles", 30},       {"sigma", 0.05},          {"kernelSize", 1},       {"lstep", 0.05},
      {"astep", 0.05},         {"iterations", 5},        {"lsigma", 0.075},       {"ogain", 3.0},
      {"lskip", 0},            {"srr", 0.1},             {"srt", 0.2},            {"str", 0.1},
      {"stt", 0.2},            {"linearUpdate", 1.0},    {"angularUpdate", 0.5},  {"temporalUpdate", -1.0},
      {"resampleThreshold", 0.5}, {"delta", 0.05},       {"xmin", -100.0},        {"ymin", -100.0},
      {"xmax", 100.0},         {"ymax", 100.0},          {"llsamplerange", 0.01}, {"llsamplestep", 0.01},
      {"lasamplerange", 0.005}, {"lasamplestep", 0.005}, {"minimumScore", 0.0},   {"seed", 0}};
  for (int i = 4; i < argc; ++i) {
    std::string kv(argv[i]);
    size_t eq = kv.find('=');
    if (eq == std::string::npos) {
      std::cerr << "argument " << kv << ": expected key=value\n";
      return 2;
    }
    std::string key = kv.substr(0, eq);
    if (!p.count(key) && key != "maxRange" && key != "maxUrange" && key != "angleIncrement") {
      std::cerr << "unknown parameter " << key << "\n";
      return 2;
    }
    p[key] = std::atof(kv.substr(eq + 1).c_str());
  }
  if (!p.count("maxRange")) {
    std::cerr << "maxRange is required (the wrapper uses the scan's range_max - 0.01)\n";
    return 2;
  }
  if (!p.count("maxUrange")) p["maxUrange"] = p["maxRange"];

  std::vector<Scan> scans = read_scans(argv[1]);
  if (scans.empty()) {
    std::cerr << argv[1] << ": no scans\n";
    return 2;
  }
  const unsigned n_beams = scans[0].ranges.size();
  double increment = p.count("angleIncrement") ? p["angleIncrement"] : M_PI / (n_beams - 1);

  GMapping::GridSlamProcessor gsp;
  // as the wrapper: one sensor named FLASER at the centred laser's origin, |increment|, span 0, maxRange
  GMapping::RangeSensor laser("FLASER", n_beams, std::fabs(increment), GMapping::OrientedPoint(0, 0, 0), 0.0,
                              p["maxRange"]);
  GMapping::SensorMap smap;
  smap.insert(std::make_pair(laser.getName(), &laser));
  gsp.setSensorMap(smap);
  GMapping::OdometrySensor odom("odom");
  (void)odom;
  GMapping::OrientedPoint initial(scans[0].x, scans[0].y, scans[0].theta);
  gsp.setMatchingParameters(p["maxUrange"], p["maxRange"], p["sigma"], int(p["kernelSize"]), p["lstep"], p["astep"],
                            int(p["iterations"]), p["lsigma"], p["ogain"], int(p["lskip"]));
  gsp.setMotionModelParameters(p["srr"], p["srt"], p["str"], p["stt"]);
  gsp.setUpdateDistances(p["linearUpdate"], p["angularUpdate"], p["resampleThreshold"]);
  gsp.setUpdatePeriod(p["temporalUpdate"]);
  gsp.setgenerateMap(false);
  gsp.GridSlamProcessor::init(int(p["particles"]), p["xmin"], p["ymin"], p["xmax"], p["ymax"], p["delta"], initial);
  gsp.setllsamplerange(p["llsamplerange"]);
  gsp.setllsamplestep(p["llsamplestep"]);
  gsp.setlasamplerange(p["lasamplerange"]);
  gsp.setlasamplestep(p["lasamplestep"]);
  gsp.setminimumScore(p["minimumScore"]);
  GMapping::sampleGaussian(1, (unsigned long)p["seed"]);  // seeds drand48 (0 leaves it unseeded, as there)

  std::ofstream neff(argv[3]);
  neff << std::fixed << std::setprecision(6);
  for (const Scan& scan : scans) {
    if (scan.ranges.size() != n_beams) {
      std::cerr << "scan at " << scan.stamp << " has " << scan.ranges.size() << " beams, not " << n_beams << "\n";
      return 2;
    }
    GMapping::RangeReading reading(n_beams, scan.ranges.data(), &laser, scan.stamp);
    reading.setPose(GMapping::OrientedPoint(scan.x, scan.y, scan.theta));
    if (gsp.processScan(reading)) neff << scan.stamp << " " << gsp.getneff() << "\n";
  }
  // the best particle's path: its tree of nodes from the last processed scan back to the first
  const GMapping::GridSlamProcessor::Particle& best = gsp.getParticles()[gsp.getBestParticleIndex()];
  std::vector<const GMapping::GridSlamProcessor::TNode*> path;
  for (const GMapping::GridSlamProcessor::TNode* n = best.node; n; n = n->parent)
    if (n->reading) path.push_back(n);
  std::ofstream out(argv[2]);
  out << std::fixed << std::setprecision(9);  // stamps of 1e9 s keep their microseconds
  for (auto it = path.rbegin(); it != path.rend(); ++it)
    out << (*it)->reading->getTime() << " " << (*it)->pose.x << " " << (*it)->pose.y << " " << (*it)->pose.theta
        << "\n";
  return 0;
}
