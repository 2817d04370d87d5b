"""Grid SLAM kernels for the Rao-Blackwellized particle filter (GMapping, Grisetti et al. T-RO 2007):
per-particle maps held as one [P, H, W] set of arrays, updated and read by one launch for all particles.

Cells are GMapping's point accumulators, one vec4 per cell (visits, hits, sx, sy): the times a beam passed
or ended in the cell, the times a beam ended in it, and the sum of those end points, so that a cell knows
where in it the walls were seen. The sums are of the end points' offsets from the cell's corner, not of
their world coordinates: in float32, a sum of a thousand hits 600 m from the origin (MIT Killian) keeps
only about 3 cm, and the matcher compares means to its 5 cm sigma (the released code sums in double).
Occupancy = hits / visits, -1 where never visited. One vec4 rather than four arrays: a lookup reads one
16-byte value (on the CPU, the matcher's cost is these cache misses).

* maps.py, ``SLAM["integrate"]``: one thread per (particle, beam) walks the cells from the laser to the end
  point (``line="bresenham"``: the 8-connected integer line between the two cells, as the released code's
  gridLine; ``line="dda"``: every cell the ray crosses, Amanatides & Woo) adding a visit to each; then one
  thread per particle adds each end point (a visit, a hit and its point) in beam order. Beams longer than
  the far bound mark free space up to it and leave the cell there untouched (the released code's
  registerScan). ``free_space=False`` skips the walk: end points only, as the released code runs with
  generateMap off (its ROS wrapper's particles). ``ParticleMaps`` holds the maps, grows them and copies
  them on resampling.
* score.py, ``SLAM["score"]``: the matcher's measurement model at candidate poses [P, C] (one thread per
  particle x candidate x beam on a GPU, x all beams on the CPU): for each beam end point, the cells of a
  (2k+1)^2 window around it that are occupied (> fullness) while the cell one free-delta before the end
  point, shifted alike, is not (``free_check=False``: occupied is enough, the released code in effect);
  mu = the end point minus the nearest such cell's mean hit point. Adds exp(-|mu|^2 / sigma) to the score
  and -|mu|^2 / lsigma (or null_likelihood / lsigma without a match) to the log-likelihood, as partial
  sums that ``reduce_partials_kernel`` adds up in beam order (the same sums on every run). Windows inside
  the map are read without a bounds check per cell.
* climb.py: GMapping's hill climbing, as launched rounds (``RBPF.match``), a particle's whole climb in one
  thread (``Scorer.climb``, the CPU's way: one launch per processed scan) or in one block of threads per
  particle (``Scorer.climb_blocks``, the GPU's way); the same poses, bit for bit.
* motion.py, ``SLAM["motion"]``: GMapping's odometry model: the odometry step in the old pose's frame, each
  component perturbed by a Gaussian whose std grows with the motion (srr, srt, str, stt). It takes the
  steps of several scans at once and applies them in order (one launch per processed scan, not per scan).

Numpy twins: irmcl_warp/reference/slam.py.
"""

# importing the files registers their entries; the names below are this package's interface
from irmcl_warp.kernels.slam.maps import (
    UNKNOWN,
    occupancy,
    cell_at,
    cell_of,
    beam_segment,
    visit,
    clear_dda,
    clear_bresenham,
    make_integrate_kernel,
    keep_slots,
    shift_cells_kernel,
    ParticleMaps,
    Integrator,
)
from irmcl_warp.kernels.slam.climb import (
    move,
    make_thread_climb_kernel,
    vec6,
    make_block_climb_kernel,
    MAX_BLOCK_BEAMS,
    block_dim_for,
    climb_candidates_kernel,
    climb_update_kernel,
)
from irmcl_warp.kernels.slam.score import (
    window_inside,
    cell_inside,
    make_window_search,
    make_score_kernel,
    reduce_partials_kernel,
    Scorer,
)
from irmcl_warp.kernels.slam.motion import motion_kernel, GmappingMotion

__all__ = [
    "UNKNOWN",
    "occupancy",
    "cell_at",
    "cell_of",
    "beam_segment",
    "visit",
    "clear_dda",
    "clear_bresenham",
    "make_integrate_kernel",
    "keep_slots",
    "shift_cells_kernel",
    "ParticleMaps",
    "Integrator",
    "move",
    "make_thread_climb_kernel",
    "vec6",
    "make_block_climb_kernel",
    "MAX_BLOCK_BEAMS",
    "block_dim_for",
    "climb_candidates_kernel",
    "climb_update_kernel",
    "window_inside",
    "cell_inside",
    "make_window_search",
    "make_score_kernel",
    "reduce_partials_kernel",
    "Scorer",
    "motion_kernel",
    "GmappingMotion",
]
