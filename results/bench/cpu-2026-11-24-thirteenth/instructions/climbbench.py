"""Micro-benchmark of the CPU climb: state after N intel scans, then time match() repeatedly."""
import sys, time, hashlib, os
import numpy as np
import warp as wp
if os.environ.get("OPT"): wp.config.optimization_level = int(os.environ["OPT"])
from irmcl_warp.config import compose_config
from irmcl_warp.services.data import load_stream
from irmcl_warp.slam.stage import start_filter

N = int(os.environ.get("N", 4000))
cfg = compose_config(["+exp=gmapping_intel", "device=cpu", "slam.num_particles=30"])
log = load_stream(cfg)
rbpf, odom = start_filter(cfg, log, "cpu")
k = 1
while k < N:
    rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k])); k += 1
# advance to the next processed scan, capture its match input
orig = rbpf.propose
cap = {}
def grab(sampled, moved):
    cap["s"] = sampled.copy()
    return orig(sampled, moved)
rbpf.propose = grab
while "s" not in cap:
    rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k])); k += 1
rbpf.propose = orig
# rbpf maps now include the scan; fine for timing: re-set the ranges of scan k-1
start = cap["s"]
times = []
for i in range(int(os.environ.get("R", 7))):
    t = time.perf_counter(); pose, best, rounds = rbpf.match(start); times.append(time.perf_counter() - t)
h = hashlib.md5(pose.tobytes() + best.tobytes()).hexdigest()
r = rbpf._climb["rounds"].numpy()
print(f"N={N} maps {rbpf.maps.shape} match ms median {1e3*np.median(times):.1f} [{1e3*min(times):.1f}-{1e3*max(times):.1f}] rounds sum {r.sum()} max {r.max()} md5 {h}")
