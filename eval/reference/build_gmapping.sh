#!/usr/bin/env bash
# Build the released GMapping (OpenSLAM, as packaged by ros-perception/openslam_gmapping) with our replay
# driver (gmapping_replay.cpp), outside the project: its code never enters this repository.
#
#   bash eval/reference/build_gmapping.sh [SRC]
#
# SRC: a clone of https://github.com/ros-perception/openslam_gmapping (a work tree or a bare repository);
# default $OPENSLAM_GMAPPING_SRC. The commit used for the figures is pinned below; the build goes to
# outputs/reference/gmapping/ (git-ignored): its sources, then the binaries gmapping_replay (a log through
# GridSlamProcessor), gmapping_motion (samples of its motion model), gmapping_matcher (its scan matcher's
# score, likelihood and hill climbing on given scans and maps), and the released gfs_nogui and gfs2log.
set -euo pipefail
PIN=5105476  # "Merge pull request #44" (2022), the newest commit of the ROS package
SRC=${1:-${OPENSLAM_GMAPPING_SRC:?give the openslam_gmapping clone as an argument or in OPENSLAM_GMAPPING_SRC}}
HERE=$(cd "$(dirname "$0")" && pwd)
OUT=${GMAPPING_BUILD:-$HERE/../../outputs/reference/gmapping}
mkdir -p "$OUT"
rm -rf "$OUT/src" && mkdir -p "$OUT/src"
git -C "$SRC" archive "$PIN" | tar x -C "$OUT/src"
echo "$PIN $(git -C "$SRC" rev-parse "$PIN")" > "$OUT/COMMIT"
# the CMake build of the package needs catkin; its export headers only declare visibility: empty here
for lib in gridfastslam log scanmatcher utils configfile sensor/sensor_base sensor/sensor_odometry sensor/sensor_range; do
  name=$(basename "$lib")
  up=$(echo "$name" | tr '[:lower:]' '[:upper:]')
  mkdir -p "$OUT/src/include/gmapping/$lib"
  printf '#pragma once\n#define %s_EXPORT\n' "$up" > "$OUT/src/include/gmapping/$lib/${name}_export.h"
done
cd "$OUT/src"
SOURCES="utils/stat.cpp utils/movement.cpp sensor/sensor_base/sensor.cpp sensor/sensor_base/sensorreading.cpp
  sensor/sensor_odometry/odometrysensor.cpp sensor/sensor_odometry/odometryreading.cpp
  sensor/sensor_range/rangesensor.cpp sensor/sensor_range/rangereading.cpp scanmatcher/scanmatcher.cpp
  scanmatcher/smmap.cpp scanmatcher/eig3.cpp gridfastslam/gridslamprocessor.cpp gridfastslam/gridslamprocessor_tree.cpp
  gridfastslam/motionmodel.cpp"
g++ -O3 -DNDEBUG -std=c++14 -w -Iinclude $SOURCES "$HERE/gmapping_replay.cpp" -o "$OUT/gmapping_replay"
g++ -O3 -DNDEBUG -std=c++14 -w -Iinclude utils/stat.cpp utils/movement.cpp gridfastslam/motionmodel.cpp \
  "$HERE/gmapping_motion.cpp" -o "$OUT/gmapping_motion"
g++ -O3 -DNDEBUG -std=c++14 -w -Iinclude $SOURCES "$HERE/gmapping_matcher.cpp" -o "$OUT/gmapping_matcher"
# the released code's own tool for CARMEN logs (gui/gfs_nogui.cpp, no Qt) and its converter of the output to
# a CARMEN log of the best particle's path (gridfastslam/gfs2log.cpp). gsp_thread.cpp streams `cout` into a
# stream, which compiles only as C++98 (an ostream's conversion to void*); libstdc++ linked statically, so the
# binaries also run on the lent GPU machine (eval/gpu/).
LOGSRC="log/carmenconfiguration.cpp log/configuration.cpp log/sensorlog.cpp log/sensorstream.cpp configfile/configfile.cpp"
g++ -O3 -DNDEBUG -std=gnu++98 -w -Iinclude -c gui/gsp_thread.cpp -o "$OUT/gsp_thread.o"
g++ -O3 -DNDEBUG -std=c++14 -w -Iinclude $SOURCES $LOGSRC "$OUT/gsp_thread.o" gui/gfs_nogui.cpp -lpthread \
  -static-libstdc++ -static-libgcc -o "$OUT/gfs_nogui"
g++ -O3 -DNDEBUG -std=gnu++98 -w -Iinclude gridfastslam/gfs2log.cpp gridfastslam/gfsreader.cpp utils/stat.cpp \
  utils/movement.cpp -static-libstdc++ -static-libgcc -o "$OUT/gfs2log"
rm -f "$OUT/gsp_thread.o"
echo "built $OUT/gmapping_replay, gmapping_motion, gmapping_matcher, gfs_nogui and gfs2log from openslam_gmapping $(cat "$OUT/COMMIT")"
