"""The keys and digits of the top-share estimate's radix select (kernels/estimate.py ``TopShareMean.SELECT``), in a
module of their own so that the launch that writes the keys (kernels/resample.py ``accumulate_max_kernel``) can
also count the select's first digit while it has them (one histogram pass fewer on a GPU).

A key is a log-weight's float bits arranged so that their ascending order is the heaviest particle first
(``heavy_first``); the select resolves ``SELECT_BITS`` of it per pass from the top (``first_digit``: the first pass).
Numpy twin: irmcl_warp/reference/estimate.py ``heavy_first_keys``.
"""

from __future__ import annotations

import warp as wp

SELECT_BITS = 11  # bits a histogram pass resolves: 2048 bins, 8 KB of shared memory
SELECT_BINS = 1 << SELECT_BITS
FIRST_SHIFT = 32 - SELECT_BITS  # the first pass reads the key's top SELECT_BITS bits


@wp.func
def heavy_first(log_w: float) -> wp.uint32:
    """A key whose ascending order is the descending order of the log-weight (the float's bits, negatives as they
    are, non-negatives with their 31 low bits flipped); -0 counts as +0, as the comparison of a sort does.
    Numpy twin: irmcl_warp/reference/estimate.py ``heavy_first_keys``."""
    x = log_w
    if x == 0.0:
        x = 0.0
    bits = wp.cast(x, wp.uint32)
    if (bits >> wp.uint32(31)) != wp.uint32(0):
        return bits
    return bits ^ wp.uint32(0x7FFFFFFF)


@wp.func
def first_digit(log_w: float) -> int:
    """The select's first digit of a log-weight: its key's top SELECT_BITS bits (every particle counts in the first
    pass: no bit of the threshold is known yet)."""
    return int(heavy_first(log_w) >> wp.uint32(FIRST_SHIFT))
