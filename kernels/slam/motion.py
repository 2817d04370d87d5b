"""``SLAM["motion"]``: GMapping's odometry motion model (drawFromMotion), the steps of several scans
applied in order in one launch.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SLAM, pick_device


@wp.kernel
def motion_kernel(
    poses: wp.array(dtype=wp.vec3),
    deltas: wp.array(dtype=wp.vec3),
    srr: float,
    srt: float,
    str_: float,
    stt: float,
    seed: int,
):
    """GMapping's drawFromMotion, once per odometry step in order: delta = the step in the old pose's frame."""
    i = wp.tid()
    state = wp.rand_init(seed, i)
    sxy = 0.3 * srr
    p = poses[i]
    for k in range(deltas.shape[0]):
        delta = deltas[k]
        ax = wp.abs(delta[0])
        ay = wp.abs(delta[1])
        at = wp.abs(delta[2])
        nx = delta[0] + wp.randn(state) * (srr * ax + str_ * at + sxy * ay)
        ny = delta[1] + wp.randn(state) * (srr * ay + str_ * at + sxy * ax)
        nt = delta[2] + wp.randn(state) * (stt * at + srt * wp.sqrt(delta[0] * delta[0] + delta[1] * delta[1]))
        c = wp.cos(p[2])
        s = wp.sin(p[2])
        t = p[2] + nt
        p = wp.vec3(p[0] + c * nx - s * ny, p[1] + s * nx + c * ny, wp.atan2(wp.sin(t), wp.cos(t)))
    poses[i] = p


class GmappingMotion:
    def __init__(self, srr: float = 0.1, srt: float = 0.2, str_: float = 0.1, stt: float = 0.2, device: str = "auto"):
        self.noise, self.device = (float(srr), float(srt), float(str_), float(stt)), pick_device(device)
        self._staged = None  # on a GPU: (device buffer, pinned host buffer, its numpy view) for the steps

    def __call__(self, poses: wp.array, deltas, seed: int) -> None:
        """Moves the poses by the odometry steps ``deltas`` ([K, 3] or one [3]), in order."""
        d = np.asarray(deltas, np.float32).reshape(-1, 3)
        wp.launch(
            motion_kernel, poses.shape[0], [poses, self._on_device(d), *self.noise, int(seed)], device=self.device
        )

    def _on_device(self, d: np.ndarray) -> wp.array:
        """The steps on the device. On a GPU through a pinned buffer kept between calls (a new device array from
        numpy would allocate and copy through pageable memory at every processed scan)."""
        if not wp.get_device(self.device).is_cuda:
            return wp.array(d, dtype=wp.vec3, device=self.device)
        if self._staged is None or self._staged[0].shape[0] < len(d):
            n = max(64, 2 * len(d))
            host = wp.empty(n, dtype=wp.vec3, device="cpu", pinned=True)
            self._staged = (wp.empty(n, dtype=wp.vec3, device=self.device), host, host.numpy())
        buf, host, view = self._staged
        wp.synchronize_stream(wp.get_stream(self.device))  # the last call's copy has run (the stream is idle here)
        view[: len(d)] = d
        wp.copy(buf, host, count=len(d))
        return buf[: len(d)]


SLAM.register("motion")(lambda **kw: GmappingMotion(**kw))
