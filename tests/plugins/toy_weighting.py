"""An observation model of your own, as a plugin (irmcl_warp/extend.py): each beam's end point scores by the map's
occupancy there, log w = sum over beams of log(0.1 + 0.9 p_occ(end)), in numpy on the host. Slow and crude, but
it localizes, and nothing in the package had to change to use it:

    python -m irmcl_warp.localize plugins=[tests/plugins/toy_weighting.py] mcl.weighting=toy_endpoint ...
"""

import numpy as np

from irmcl_warp.kernels import WEIGHTING

CALLS = [0]  # how often it scored a scan (tests/test_extend.py reads it)


class EndPointOccupancy:
    capturable = False  # host code: a GPU step cannot replay it as a graph

    def __init__(self, occupancy, origin_xy, resolution_m, device, **unused):
        self.occupancy, self.origin, self.res, self.device = np.asarray(occupancy), origin_xy, resolution_m, device

    def __call__(self, particles, T_base_laser, angles, measured, log_weights):
        CALLS[0] += 1
        p, a, z = particles.numpy().astype(np.float64), angles.numpy(), measured.numpy()
        tx, ty, tyaw = T_base_laser
        lx = p[:, 0] + np.cos(p[:, 2]) * tx - np.sin(p[:, 2]) * ty  # the laser in the map
        ly = p[:, 1] + np.sin(p[:, 2]) * tx + np.cos(p[:, 2]) * ty
        heading = p[:, 2:3] + tyaw + a[None]
        ok = np.isfinite(z)
        ex = lx[:, None] + np.cos(heading[:, ok]) * z[ok]
        ey = ly[:, None] + np.sin(heading[:, ok]) * z[ok]
        ix = np.floor((ex - self.origin[0]) / self.res).astype(int)
        iy = np.floor((ey - self.origin[1]) / self.res).astype(int)
        H, W = self.occupancy.shape
        inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
        p_occ = np.where(inside, self.occupancy[iy.clip(0, H - 1), ix.clip(0, W - 1)], 0.0)
        log_weights.assign(np.log(0.1 + 0.9 * p_occ).sum(1).astype(np.float32))


@WEIGHTING.register("toy_endpoint")
def make_toy(**settings):
    return EndPointOccupancy(**settings)
